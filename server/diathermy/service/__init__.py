"""The simulation service: FastAPI app, sessions over REST, WebSocket streaming.

FastAPI is imported only under this package, and only when the app is built, so that
``diathermy simulate`` never pays for it.
"""

from __future__ import annotations

from typing import Any

__all__ = ["Settings", "create_app"]


def __getattr__(name: str) -> Any:
    if name == "create_app":
        from diathermy.service.main import create_app

        return create_app
    if name == "Settings":
        from diathermy.service.config import Settings

        return Settings
    raise AttributeError(name)
