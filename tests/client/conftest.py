"""The SDK against a real uvicorn server with the real engine (the service tests' LiveServer)."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT / "client") not in sys.path:
    sys.path.insert(0, str(ROOT / "client"))

from diathermy.service.engine import DefaultEngine  # noqa: E402
from diathermy_client import Client  # noqa: E402
from tests.service.conftest import CUT, TOKEN_A, TOKEN_B, LiveServer, make_settings  # noqa: E402

__all__ = ["CUT", "TOKEN_A", "TOKEN_B", "LiveServer", "make_settings"]

SMALL_GRID = (5, 5, 9)
QUICK_CUT_SCENE = CUT["scene"]


@pytest.fixture()
def live(tmp_path: Path) -> Iterator[LiveServer]:
    server = LiveServer(make_settings(tmp_path / "data"), DefaultEngine()).start()
    yield server
    server.stop()


@pytest.fixture()
def client(live: LiveServer) -> Iterator[Client]:
    with Client(live.url, TOKEN_A, timeout_s=30) as c:
        yield c
