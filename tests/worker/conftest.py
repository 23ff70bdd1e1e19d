"""A live server and real ``diathermy worker`` processes sharing one data directory."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from diathermy.service.engine import DefaultEngine
from tests.service.conftest import LiveServer, make_settings

ROOT = Path(__file__).resolve().parents[2]
TINY = {"grid": [5, 5, 9], "n_scenarios": 3, "n_steps": 2, "seed": 3}


class WorkerProcess:
    """``python -m diathermy worker`` on the server's data directory."""

    def __init__(self, data_dir: Path, log: Path, *, lease_s: float = 3.0) -> None:
        env = {**os.environ, "PYTHONPATH": str(ROOT / "server"), "OMP_NUM_THREADS": "1"}
        self.log = log.open("w")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "diathermy", "worker", "--data-dir", str(data_dir),
             "--poll-s", "0.1", "--lease-s", str(lease_s)],
            stdout=self.log, stderr=subprocess.STDOUT, env=env, cwd=ROOT,
        )  # fmt: skip

    def kill(self) -> None:
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=10)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.kill()
        self.log.close()


@pytest.fixture()
def live(tmp_path: Path) -> Iterator[LiveServer]:
    server = LiveServer(make_settings(tmp_path / "data"), DefaultEngine()).start()
    yield server
    server.stop()


@pytest.fixture()
def api(live: LiveServer) -> Iterator[httpx.Client]:
    with live.client() as c:
        yield c


@pytest.fixture()
def start_worker(live: LiveServer, tmp_path: Path) -> Iterator[Callable[..., WorkerProcess]]:
    started: list[WorkerProcess] = []

    def start(**kwargs: Any) -> WorkerProcess:
        w = WorkerProcess(live.settings.data_dir, tmp_path / f"worker{len(started)}.log", **kwargs)
        started.append(w)
        return w

    yield start
    for w in started:
        w.stop()


def wait_for(
    api: httpx.Client, job_id: str, until: Callable[[dict], bool], timeout_s: float = 60
) -> dict:
    """Poll GET /v1/jobs/{id} until ``until(job)``; fail with the job's log on timeout."""
    deadline = time.monotonic() + timeout_s
    while True:
        job = api.get(f"/v1/jobs/{job_id}").json()
        if until(job):
            return job
        if time.monotonic() > deadline:
            log = api.get(f"/v1/jobs/{job_id}/log").json()
            raise AssertionError(f"timed out: {job}\n{log}")
        time.sleep(0.1)


def log_lines(api: httpx.Client, job_id: str) -> list[str]:
    return [x["line"] for x in api.get(f"/v1/jobs/{job_id}/log").json()["lines"]]
