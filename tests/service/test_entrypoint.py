"""The Dockerfile's command, run here as a subprocess with its environment (Docker cannot run)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import httpx

from tests.service.conftest import TOKEN_A, free_port

ROOT = Path(__file__).resolve().parents[2]


def dockerfile_command() -> tuple[list[str], dict[str, str]]:
    """The CMD (exec form) and the ENV values of the Dockerfile."""
    lines = (ROOT / "Dockerfile").read_text().replace("\\\n", " ").splitlines()
    env: dict[str, str] = {}
    cmd: list[str] = []
    for line in lines:
        if line.startswith("ENV "):
            for pair in line[4:].split():
                key, _, value = pair.partition("=")
                env[key] = value
        elif line.startswith("CMD "):
            cmd = json.loads(line[4:])
    return cmd, env


def start(cmd: list[str], env: dict[str, str]) -> subprocess.Popen[str]:
    assert cmd[0] == "diathermy"  # the console script; here: this interpreter and worktree
    full_env = {**os.environ, **env, "PYTHONPATH": str(ROOT / "server")}
    return subprocess.Popen(
        [sys.executable, "-m", "diathermy", *cmd[1:]],
        env=full_env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def wait_healthy(url: str, proc: subprocess.Popen[str]) -> None:
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()[1]
        try:
            if httpx.get(url + "/healthz").status_code == 200:
                return
        except httpx.TransportError:
            time.sleep(0.1)
    raise AssertionError("server did not come up")


def stop(proc: subprocess.Popen[str]) -> str:
    proc.terminate()
    _, err = proc.communicate(timeout=30)
    return err


def test_docker_command_serves_with_env_settings(tmp_path: Path) -> None:
    cmd, env = dockerfile_command()
    assert cmd == ["diathermy", "serve"] and env["DIATHERMY_HOST"] == "0.0.0.0"
    port = free_port()
    env.update(
        DIATHERMY_HOST="127.0.0.1",
        DIATHERMY_PORT=str(port),
        DIATHERMY_DATA_DIR=str(tmp_path / "data"),
        DIATHERMY_TOKENS=TOKEN_A,
    )
    proc = start(cmd, env)
    url = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(url, proc)
        assert httpx.get(url + "/readyz").json()["status"] == "ok"
        assert httpx.get(url + "/v1/sessions").status_code == 401
        headers = {"Authorization": f"Bearer {TOKEN_A}"}
        assert httpx.get(url + "/v1/sessions", headers=headers).json() == {"sessions": []}
    finally:
        err = stop(proc)
    records = [json.loads(line) for line in err.splitlines() if line.strip()]  # JSON logs only
    assert any(r["message"] == "ready" for r in records)
    assert any(r["message"] == "stopped" for r in records)  # graceful shutdown on SIGTERM
    assert any(r.get("path") == "/v1/sessions" and r.get("status") == 401 for r in records)
    assert (tmp_path / "data" / "sessions").is_dir()


def test_no_auth_warns_and_no_tokens_refuses(tmp_path: Path) -> None:
    port = free_port()
    env = {"DIATHERMY_PORT": str(port), "DIATHERMY_DATA_DIR": str(tmp_path / "d")}
    proc = start(["diathermy", "serve", "--no-auth"], env)
    try:
        wait_healthy(f"http://127.0.0.1:{port}", proc)
        assert httpx.get(f"http://127.0.0.1:{port}/v1/sessions").status_code == 200
    finally:
        err = stop(proc)
    warnings = [json.loads(x) for x in err.splitlines() if '"WARNING"' in x]
    assert any("DISABLED" in w["message"] for w in warnings)

    env.pop("DIATHERMY_TOKENS", None)
    proc = start(["diathermy", "serve"], {**env, "DIATHERMY_TOKENS": ""})
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 2 and "no bearer tokens configured" in err
    assert "Traceback" not in err
