"""The published contracts: ``openapi/openapi.json`` (REST) and ``openapi/stream-messages.json``."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Any

from diathermy.service.config import Settings
from diathermy.service.main import create_app
from diathermy.service.messages import stream_messages_schema


def openapi_document() -> dict[str, Any]:
    """The OpenAPI document of the app (independent of any server's settings)."""
    with tempfile.TemporaryDirectory() as tmp:
        app = create_app(Settings(auth_disabled=True, data_dir=Path(tmp)))
        return app.openapi()


def contract_files() -> dict[str, str]:
    """File name -> text of every published contract."""
    dump = lambda d: json.dumps(d, indent=2, sort_keys=True) + "\n"  # noqa: E731
    return {
        "openapi.json": dump(openapi_document()),
        "stream-messages.json": dump(stream_messages_schema()),
    }


def write_contracts(out_dir: Path) -> list[Path]:
    """Write the contract files into ``out_dir``; returns their paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, text in contract_files().items():
        path = out_dir / name
        path.write_text(text, encoding="utf-8")
        paths.append(path)
    return paths
