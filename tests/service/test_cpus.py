"""CPU placement (DIATHERMY_ENGINE_CPUS, ``diathermy serve --engine-cpus``): the setting is parsed
and checked at start-up, each engine process runs on the CPUs given and the server on the rest;
unset, nothing is placed."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import httpx
import pytest
from pydantic import ValidationError

from diathermy.service import Settings
from diathermy.service.cpus import check_engine_cpus, format_cpus, parse_cpus
from diathermy.service.engine import DefaultEngine
from tests.service.conftest import SMALL, LiveServer, descendants, free_port, make_settings
from tests.service.test_entrypoint import start, stop, wait_healthy

ALLOWED = sorted(os.sched_getaffinity(0))
multi_core = pytest.mark.skipif(len(ALLOWED) < 2, reason="needs 2 CPUs to place engines apart")


def test_cpu_lists_parse_like_taskset() -> None:
    assert parse_cpus("1") == [1]
    assert parse_cpus(" 2-4, 0 ,3") == [0, 2, 3, 4]
    assert parse_cpus("") == []
    for bad in ("one", "3-1", "-1", "1-x", "1.5"):
        with pytest.raises(ValueError, match="CPU"):
            parse_cpus(bad)
    assert format_cpus([5, 0, 1, 2, 7, 8]) == "0-2,5,7-8"


def test_engine_cpus_must_be_usable_and_leave_one_for_the_server() -> None:
    assert check_engine_cpus([], allowed={0, 1}) == []
    assert check_engine_cpus([1], allowed={0, 1}) == [1]
    with pytest.raises(ValueError, match=r"engine CPU\(s\) 2-3 not among .* \(0-1\)"):
        check_engine_cpus([1, 2, 3], allowed={0, 1})
    with pytest.raises(ValueError, match="leave no CPU for the server"):
        check_engine_cpus([0, 1], allowed={0, 1})


def test_the_setting_is_read_from_the_environment_and_checked(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    assert Settings().engine_cpus == []  # the default: no placement
    monkeypatch.setenv("DIATHERMY_ENGINE_CPUS", str(ALLOWED[-1]))
    if len(ALLOWED) >= 2:
        assert Settings().engine_cpus == [ALLOWED[-1]]
    monkeypatch.setenv("DIATHERMY_ENGINE_CPUS", str(max(ALLOWED) + 1))
    with pytest.raises(ValidationError, match="not among the CPUs this process may run on"):
        Settings()


def test_a_bad_value_stops_serve_with_one_line(tmp_path: Path) -> None:
    for value in (str(max(ALLOWED) + 1), "1-x"):
        proc = subprocess.run(
            [sys.executable, "-m", "diathermy", "serve", "--no-auth", "--engine-cpus", value],
            capture_output=True,
            text=True,
            env={**os.environ, "DIATHERMY_DATA_DIR": str(tmp_path / "d")},
            timeout=60,
        )
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1, proc.stderr
        assert lines[0].startswith("diathermy: error: engine_cpus: ") and "CPU" in lines[0]


@multi_core
def test_engine_processes_run_on_the_engine_cpus(tmp_path: Path) -> None:
    """Through a real server: a created session's engine, and one loaded again after its
    process ended, run on the CPUs given; the app itself pins nothing (``serve`` does)."""
    engine = ALLOWED[-1]
    settings = make_settings(tmp_path / "data", engine_cpus=[engine])
    server = LiveServer(settings, DefaultEngine()).start()
    try:
        with server.client() as api:
            sid = api.post("/v1/sessions", json=SMALL).json()["id"]
            sim = server.state.registry.sessions[sid].sim
            assert os.sched_getaffinity(sim.pid) == {engine}
            sim.close()  # the next use loads it in a new process
            assert api.post(f"/v1/sessions/{sid}/step").status_code == 200
            again = server.state.registry.sessions[sid].sim
            assert again.pid != sim.pid and os.sched_getaffinity(again.pid) == {engine}
        assert sorted(os.sched_getaffinity(0)) == ALLOWED
    finally:
        server.stop()


@multi_core
def test_serve_pins_the_server_to_the_other_cpus(tmp_path: Path) -> None:
    engine = ALLOWED[-1]
    port = free_port()
    env = {"DIATHERMY_PORT": str(port), "DIATHERMY_DATA_DIR": str(tmp_path / "d")}
    proc = start(["diathermy", "serve", "--no-auth", "--engine-cpus", str(engine)], env)
    url = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(url, proc)
        assert os.sched_getaffinity(proc.pid) == set(ALLOWED) - {engine}
        assert httpx.post(url + "/v1/sessions", json=SMALL, timeout=60).status_code == 201
        placed = {p: os.sched_getaffinity(p) for p in descendants(proc.pid)}
        assert {engine} in placed.values(), placed  # the engine process
        tasks = Path(f"/proc/{proc.pid}/task").iterdir()  # every thread of the server
        assert all(os.sched_getaffinity(int(t.name)) == set(ALLOWED) - {engine} for t in tasks)
    finally:
        err = stop(proc)
    assert '"cpu placement"' in err and f'"engine_cpus": "{engine}"' in err
