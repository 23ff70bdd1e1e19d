"""The service benchmark's server: the app with the real engine under uvicorn in a child
process (``serve_child``, run as ``service.py serve-child``), and the handle that starts it,
waits for it and opens sessions on it (``Server``)."""

from __future__ import annotations

import argparse
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import httpx

from diathermy.scene.builtin import builtin_scene

SERVICE_SCRIPT = Path(__file__).with_name("service.py")
"""The script whose ``serve-child`` command runs the server child (``Server``'s default)."""
TOKEN = "bench-token"
DEFAULT_RESOLUTION = builtin_scene("default").resolution.model_dump(mode="json")  # type: ignore[union-attr]
"""The default scene's graded grid (``--grids default``)."""
DEFAULT_LABEL = (
    "x".join(map(str, builtin_scene("default").node_shape)) + " (the default scene's graded grid)"
)
"""The heading of the default grid's table."""


def serve_child(args: argparse.Namespace) -> None:
    """The child process: the app with the real engine under uvicorn."""
    import uvicorn

    from diathermy.runtime import configure_threads
    from diathermy.service import Settings, create_app
    from diathermy.service.cpus import place_server
    from diathermy.service.jsonlog import configure_logging

    configure_threads()  # as `diathermy serve` does: one BLAS thread per engine

    settings = Settings(
        port=args.port,
        data_dir=Path(args.data_dir),
        tokens=[TOKEN],
        max_stream_rate_hz=1000.0,
        max_sessions_per_token=64,
        autosave_interval_s=3600,
        log_level="WARNING",
    )
    configure_logging("WARNING")
    place_server(settings.engine_cpus)  # as `diathermy serve` does (DIATHERMY_ENGINE_CPUS)
    app = create_app(settings)
    uvicorn.run(
        app,
        host="127.0.0.1",
        port=args.port,
        ws="websockets-sansio",
        ws_per_message_deflate=False,
        log_config=None,
        access_log=False,
        ws_max_size=settings.max_message_bytes,
    )


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Server:
    def __init__(
        self, data_dir: Path, script: Path | None = None, env: dict[str, str] | None = None
    ) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.ws = f"ws://127.0.0.1:{self.port}"
        self.proc = subprocess.Popen(
            [
                sys.executable,
                str(script or SERVICE_SCRIPT),
                "serve-child",
                "--port",
                str(self.port),
                "--data-dir",
                str(data_dir),
            ],
            env=env,
        )
        self.wait_ready(timeout_s=60.0)
        self.http = httpx.Client(
            base_url=self.url, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=120
        )

    def wait_ready(self, timeout_s: float) -> None:
        """Poll ``/readyz``; raise at once if the server exits, or after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while True:
            code = self.proc.poll()
            if code is not None:
                raise RuntimeError(f"the benchmark server exited with code {code} before ready")
            try:
                if httpx.get(self.url + "/readyz", timeout=5).status_code == 200:
                    return
            except httpx.TransportError:
                pass
            if time.monotonic() > deadline:
                self.stop()
                raise RuntimeError(f"the benchmark server was not ready after {timeout_s:.0f} s")
            time.sleep(0.1)

    def session(self, grid: list[int] | None, scene: dict[str, Any] | None = None) -> str:
        """A new session on ``grid`` (None: the default scene's own graded grid)."""
        if grid is None:
            own = {"resolution": DEFAULT_RESOLUTION}
            body: dict[str, Any] = {"scene": {**(scene or {}), **own}}
        else:
            body = (
                {"scene": {**scene, "grid": grid}}
                if scene
                else {"builtin": "default", "grid": grid}
            )
        r = self.http.post("/v1/sessions", json=body)
        r.raise_for_status()
        return str(r.json()["id"])

    def step_until_cut(self, sid: str, max_steps: int = 40) -> int:
        for _ in range(max_steps):
            rep = self.http.post(f"/v1/sessions/{sid}/step").json()["reports"][-1]
            if rep["cut_volume_m3"]:
                return int(rep["step"])
        raise RuntimeError("no cut")

    def stop(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
