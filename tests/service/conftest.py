"""A real uvicorn server on a free localhost port, in a background thread, per test."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import uvicorn

from diathermy.service import Settings, create_app
from diathermy.service.engine import DefaultEngine

TOKEN_A = "token-alpha"
TOKEN_B = "token-bravo"
SMALL = {"builtin": "default", "grid": [5, 5, 9]}
CUT = {
    "scene": {
        "name": "quick-cut",
        "block_m": [0.02, 0.01, 0.01],
        "grid": [5, 5, 9],
        "electrodes": [{"position_m": [0.01, 0.005], "power_w": 200.0}],
    }
}
"""A 2 x 1 x 1 cm block under a 200 W electrode: the real engine cuts it within ~10 steps."""


def step_until_cut(api: httpx.Client, sid: str, max_steps: int = 30) -> int:
    """Step a session one step at a time until its last report shows a cut; returns the step."""
    for _ in range(max_steps):
        rep = api.post(f"/v1/sessions/{sid}/step").json()["reports"][-1]
        if rep["cut_volume_m3"] > 0:
            return int(rep["step"])
    raise AssertionError(f"no cut within {max_steps} steps")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class LiveServer:
    """uvicorn serving the app in a thread; ``stop`` runs the app's shutdown (checkpoints)."""

    def __init__(self, settings: Settings, engine: Any) -> None:
        self.settings = settings
        self.app = create_app(settings, engine=engine)
        config = uvicorn.Config(
            self.app,
            host="127.0.0.1",
            port=settings.port,
            ws="websockets-sansio",
            ws_per_message_deflate=False,
            ws_max_size=settings.max_message_bytes,
            log_config=None,
            access_log=False,
            lifespan="on",
        )
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)
        self.url = f"http://127.0.0.1:{settings.port}"
        self.ws_url = f"ws://127.0.0.1:{settings.port}"

    def start(self) -> LiveServer:
        self.thread.start()
        deadline = time.monotonic() + 20
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise RuntimeError("server did not start")
            time.sleep(0.02)
        return self

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=30)

    @property
    def state(self) -> Any:
        return self.app.state.diathermy

    def client(self, token: str | None = TOKEN_A) -> httpx.Client:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        return httpx.Client(base_url=self.url, headers=headers, timeout=30)


def make_settings(data_dir: Path, **overrides: Any) -> Settings:
    base: dict[str, Any] = {
        "port": free_port(),
        "data_dir": data_dir,
        "tokens": [TOKEN_A, TOKEN_B],
        "max_grid_nodes": 5000,
        "max_steps_per_request": 50,
        "max_sessions_per_token": 4,
        "max_request_bytes": 200_000,
        "max_message_bytes": 8192,
        "max_stream_rate_hz": 200.0,
        "autosave_interval_s": 3600.0,
    }
    base.update(overrides)
    return Settings(**base)


@pytest.fixture()
def live(tmp_path: Path) -> Iterator[LiveServer]:
    server = LiveServer(make_settings(tmp_path / "data"), DefaultEngine()).start()
    yield server
    server.stop()


@pytest.fixture()
def api(live: LiveServer) -> Iterator[httpx.Client]:
    with live.client() as c:
        yield c


def descendants(pid: int) -> list[int]:
    """Child processes of ``pid``, recursively (a server's forkserver and engine processes)."""
    out: list[int] = []
    for task in Path(f"/proc/{pid}/task").glob("*/children"):
        for child in task.read_text().split():
            out += [int(child), *descendants(int(child))]
    return out


def running(pid: int) -> bool:
    """Whether ``pid`` is a live process (neither gone nor a zombie)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError):  # gone, or reaped while being read (ESRCH)
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def assert_ended(pids: list[int], timeout_s: float = 10.0) -> None:
    """Every process of ``pids`` ends within ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while any(running(p) for p in pids):
        assert time.monotonic() < deadline, f"still running: {[p for p in pids if running(p)]}"
        time.sleep(0.05)
