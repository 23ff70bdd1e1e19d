"""No acknowledged step is lost on kill -9: a real ``diathermy serve`` process is SIGKILLed at a
random moment while a client steps it over REST or streams it, then restarted on the same data
directory. Every acknowledged step must be there, and the fields must equal, bit for bit, an
uninterrupted in-process run of the same commands in the same order.

Acknowledged: a REST reply received, a stream frame received, an electrode ack received (its
``step`` says after which step it applied). A command in flight at the kill may or may not have
been journalled; the checks allow both.
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from diathermy.engine.simulation import Simulation
from diathermy.scene import builtin_scene, scene_from_dict
from diathermy.service.encoding import decode_array, unpack
from tests.service.conftest import TOKEN_A, assert_ended, descendants, free_port

ROOT = Path(__file__).resolve().parents[2]
GRID = (9, 9, 17)
HEADERS = {"Authorization": f"Bearer {TOKEN_A}"}
Command = tuple[str, Any]  # ("step", None) or ("electrode", {changes})


class Server:
    """``python -m diathermy serve`` on a data directory; ``kill`` is SIGKILL."""

    def __init__(self, data: Path, log: Path, autosave_s: float) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        env = {
            **os.environ,
            "PYTHONPATH": os.pathsep.join([str(ROOT / "server"), str(ROOT / "client")]),
            "DIATHERMY_TOKENS": TOKEN_A,
            "DIATHERMY_MAX_STREAM_RATE_HZ": "1000",
            "DIATHERMY_AUTOSAVE_INTERVAL_S": str(autosave_s),  # compactions at random moments too
        }
        self.log = log.open("a")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "diathermy", "serve", "--port", str(self.port)]
            + ["--data-dir", str(data)],
            env=env,
            stdout=self.log,
            stderr=self.log,
        )
        deadline = time.monotonic() + 60
        while True:
            assert self.proc.poll() is None, log.read_text()[-2000:]
            try:
                if httpx.get(self.url + "/readyz").status_code == 200:
                    break
            except httpx.TransportError:
                pass
            assert time.monotonic() < deadline, "server did not come up"
            time.sleep(0.05)
        self.api = httpx.Client(base_url=self.url, headers=HEADERS, timeout=30)
        self.children: list[int] = []  # the processes it had started when it was killed

    def kill_after(self, delay_s: float) -> threading.Thread:
        def kill() -> None:
            time.sleep(delay_s)
            self.children = descendants(self.proc.pid)
            self.proc.kill()

        thread = threading.Thread(target=kill, daemon=True)
        thread.start()
        return thread

    def close(self) -> None:
        self.api.close()
        if self.proc.poll() is None:
            self.proc.terminate()
        self.proc.wait(timeout=30)
        self.log.close()


def scene_body() -> dict[str, Any]:
    return {"scene": builtin_scene("default").on_uniform_grid(GRID).model_dump(mode="json")}


def server_fields(api: httpx.Client, sid: str, names: list[str]) -> dict[str, np.ndarray]:
    r = api.get(
        f"/v1/sessions/{sid}/fields", params={"fields": ",".join(names), "dtype": "float64"}
    )
    assert r.status_code == 200, r.text
    return {n: decode_array(a) for n, a in unpack(r.content)["fields"].items()}


def replay_reference(commands: list[Command], steps: int) -> Simulation:
    """An uninterrupted run: the commands in order, until ``steps`` steps were taken."""
    sim = Simulation(scene_from_dict(scene_body()["scene"]))
    for kind, data in commands:
        if kind == "electrode":
            sim.set_electrode("active", **data)
        elif sim.step_index < steps:
            sim.step()
    assert sim.step_index == steps, "the server holds steps nobody asked for"
    return sim


def assert_recovered(api: httpx.Client, sid: str, commands: list[Command], steps: int) -> None:
    ref = replay_reference(commands, steps)
    got = server_fields(api, sid, list(ref.field_names()))
    for name in ref.field_names():
        expected = np.asarray(ref.field(name))
        np.testing.assert_array_equal(got[name], expected.astype(got[name].dtype), err_msg=name)


def rest_round(
    server: Server, sid: str, rng: random.Random, commands: list[Command]
) -> tuple[int, dict[str, Any] | None]:
    """PATCH and step at random until the server dies; returns (steps acknowledged, the
    electrode change in flight at the kill if any)."""
    server.kill_after(rng.uniform(0.4, 1.5))
    while True:
        acked = sum(kind == "step" for kind, _ in commands)
        if rng.random() < 0.3:
            change: dict[str, Any] = (
                {"power_w": round(rng.uniform(10, 80), 3)}
                if rng.random() < 0.7
                else {"position_m": [round(rng.uniform(0.05, 0.15), 4), 0.05]}
            )
            commands.append(("electrode", change))
            try:
                r = server.api.patch(f"/v1/sessions/{sid}/electrodes/active", json=change)
            except httpx.TransportError:
                return acked, change
            assert r.status_code == 200, r.text
        else:
            n = rng.randint(1, 4)
            commands.extend([("step", None)] * n)  # in flight: the reference stops at the count
            try:
                r = server.api.post(f"/v1/sessions/{sid}/step", json={"n": n})
            except httpx.TransportError:
                return acked, None
            assert r.status_code == 200 and r.json()["step"] == acked + n, r.text


def drop_steps_not_taken(commands: list[Command], steps: int) -> None:
    """Forget the in-flight steps the server never journalled (they are always the last ones)."""
    while sum(kind == "step" for kind, _ in commands) > steps:
        del commands[max(i for i, (kind, _) in enumerate(commands) if kind == "step")]


def test_kill_9_during_rest_steps_loses_no_acknowledged_step(tmp_path: Path) -> None:
    rng = random.Random(int.from_bytes(os.urandom(4), "little"))
    data, log = tmp_path / "data", tmp_path / "server.log"
    server = Server(data, log, autosave_s=rng.uniform(0.2, 1.0))
    sid = server.api.post("/v1/sessions", json=scene_body()).json()["id"]
    commands: list[Command] = []
    figures = []
    try:
        for _ in range(2):
            acked, in_flight = rest_round(server, sid, rng, commands)
            server.proc.wait(timeout=30)
            assert server.proc.returncode == -9
            assert len(server.children) >= 2  # the forkserver and the session's engine
            assert_ended(server.children)  # no orphan engine process
            server.close()
            server = Server(data, log, autosave_s=rng.uniform(0.2, 1.0))
            step = server.api.get(f"/v1/sessions/{sid}").json()["step"]
            figures.append((acked, step))
            assert step >= acked, f"acknowledged {acked} steps, recovered {step}"
            assert_recovered(server.api, sid, commands, step)
            drop_steps_not_taken(commands, step)
            if in_flight is not None:  # journalled or not: sending it again makes it certain
                server.api.patch(f"/v1/sessions/{sid}/electrodes/active", json=in_flight)
    finally:
        server.close()
    print(f"kill -9 during REST steps (acknowledged, recovered): {figures}")


def test_kill_9_during_a_stream_loses_no_acknowledged_step(tmp_path: Path) -> None:
    rng = random.Random(int.from_bytes(os.urandom(4), "little"))
    data, log = tmp_path / "data", tmp_path / "server.log"
    server = Server(data, log, autosave_s=rng.uniform(0.2, 1.0))
    sid = server.api.post("/v1/sessions", json=scene_body()).json()["id"]
    controls: list[tuple[int, dict[str, Any]]] = []  # (applied after step, changes)
    figures = []
    try:
        for _ in range(2):
            kill_at = time.monotonic() + rng.uniform(0.5, 1.5)
            acked = stream_round(server, sid, rng, controls, kill_at)
            server.proc.wait(timeout=30)
            assert len(server.children) >= 2
            assert_ended(server.children)
            server.close()
            server = Server(data, log, autosave_s=rng.uniform(0.2, 1.0))
            step = server.api.get(f"/v1/sessions/{sid}").json()["step"]
            figures.append((acked, step))
            assert step >= acked, f"acknowledged {acked} steps, recovered {step}"
            commands: list[Command] = []
            for k in range(step + 1):
                commands += [("electrode", c) for s, c in controls if s == k]
                commands.append(("step", None))
            assert_recovered(server.api, sid, commands, step)
    finally:
        server.close()
    print(f"kill -9 during a stream (acknowledged, recovered): {figures}")


def stream_round(
    server: Server,
    sid: str,
    rng: random.Random,
    controls: list[tuple[int, dict[str, Any]]],
    kill_at: float,
) -> int:
    """Run the session over the stream, re-power it at random, die at ``kill_at``; returns the
    highest step a frame acknowledged. Controls stop 0.3 s before the kill: each is acked (with the
    step it applied after) before the next, so none is in flight when the server dies."""
    server.kill_after(kill_at - time.monotonic())
    seen = 0
    url = f"ws://127.0.0.1:{server.port}/v1/sessions/{sid}/stream"
    with connect(url, additional_headers=HEADERS, open_timeout=10, max_size=None) as ws:
        assert unpack(ws.recv(timeout=10))["type"] == "hello"
        ws.send(json.dumps({"type": "subscribe", "fields": ["temperature"]}))
        ws.send(json.dumps({"type": "run", "rate_hz": 1000}))
        waiting: dict[str, Any] | None = None
        next_control = time.monotonic() + rng.uniform(0.02, 0.2)
        try:
            while True:
                now = time.monotonic()
                if waiting is None and now < kill_at - 0.3 and now >= next_control:
                    waiting = {"power_w": round(rng.uniform(10, 80), 3)}
                    ws.send(json.dumps({"type": "electrode", **waiting, "tag": len(controls)}))
                msg = unpack(ws.recv(timeout=10))
                if msg["type"] == "frame":
                    seen = max(seen, int(msg["step"]))
                elif msg["type"] == "ack" and msg["of"] == "electrode":
                    assert waiting is not None and msg["tag"] == len(controls)
                    controls.append((int(msg["step"]), waiting))
                    waiting = None
                    next_control = time.monotonic() + rng.uniform(0.02, 0.2)
        except (ConnectionClosed, OSError):
            pass
    assert waiting is None, "a control was in flight at the kill"
    return seen
