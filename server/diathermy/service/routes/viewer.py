"""The browser viewer: static files (page, style, the built bundle) under ``/viewer``.

The bundle ``viewer.js`` is built from ``viewer/`` (npm libraries, lock file) by the set-up
command and shipped as package data; nothing is fetched from the internet at run time. The page
talks to the service through the documented REST and WebSocket API only.
"""

from __future__ import annotations

import logging
from pathlib import Path

from fastapi import FastAPI
from fastapi.responses import RedirectResponse
from fastapi.staticfiles import StaticFiles

STATIC_DIR = Path(__file__).resolve().parent.parent / "static" / "viewer"
BUNDLE = STATIC_DIR / "viewer.js"

log = logging.getLogger("diathermy.service.viewer")


def mount_viewer(app: FastAPI) -> None:
    """Serve the viewer at ``/viewer/`` (``/viewer`` redirects there); warn if unbuilt."""
    if not BUNDLE.is_file():
        log.warning(
            "viewer bundle missing; /viewer will not work until it is built",
            extra={"bundle": str(BUNDLE), "build": "cd viewer && npm ci && npm run build"},
        )

    @app.get("/viewer", include_in_schema=False)
    async def viewer_root() -> RedirectResponse:
        return RedirectResponse("/viewer/", status_code=307)

    app.mount("/viewer", StaticFiles(directory=STATIC_DIR, html=True), name="viewer")
