"""The process boundary: each loaded session's engine runs in a process of its own. One that dies
is an error the client sees at once (not a hang) and the session carries on from its journal;
DELETE and shutdown end the processes."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import httpx
import pytest

from diathermy.scene import builtin_scene
from diathermy.service import engine_ops as ops
from diathermy.service.encoding import unpack
from diathermy.service.engine import DefaultEngine
from diathermy.service.engine_process import RemoteSim
from diathermy.service.exceptions import NotFoundError
from diathermy.service.hub import Subscription
from tests.service.conftest import SMALL, LiveServer, assert_ended, make_settings, running
from tests.service.test_stream import open_stream, recv_type


def engine_pid(live: LiveServer, sid: str) -> int:
    sim = live.state.registry.sessions[sid].sim
    assert sim is not None and sim.pid is not None and sim.pid != os.getpid()
    return int(sim.pid)


def test_a_dead_engine_is_a_clear_error_then_the_session_reloads(
    live: LiveServer, api: httpx.Client
) -> None:
    sid = api.post("/v1/sessions", json=SMALL).json()["id"]
    assert api.post(f"/v1/sessions/{sid}/step", json={"n": 3}).json()["step"] == 3
    pid = engine_pid(live, sid)
    os.kill(pid, signal.SIGKILL)
    assert_ended([pid])
    r = api.post(f"/v1/sessions/{sid}/step")
    assert r.status_code == 503, r.text
    body = r.json()
    assert body["error"] == "engine_failed" and "signal 9" in body["message"], body
    r = api.post(f"/v1/sessions/{sid}/step")  # a new engine process, replayed from the journal
    assert r.status_code == 200 and r.json()["step"] == 4, r.text
    assert engine_pid(live, sid) != pid


def test_a_dead_engine_stops_the_stream_with_an_error(live: LiveServer, api: httpx.Client) -> None:
    sid = api.post("/v1/sessions", json=SMALL).json()["id"]
    with open_stream(live, sid) as ws:
        recv_type(ws, "hello")
        ws.send(json.dumps({"type": "subscribe", "fields": ["temperature"]}))
        ws.send(json.dumps({"type": "run", "rate_hz": 50}))
        recv_type(ws, "frame")
        os.kill(engine_pid(live, sid), signal.SIGKILL)
        err = recv_type(ws, "error", timeout=10)
        assert err["error"] == "engine_failed", err
        ws.send(json.dumps({"type": "run", "rate_hz": 50}))  # resumes on a reloaded engine
        step = recv_type(ws, "frame", timeout=10)["step"]
        assert recv_type(ws, "frame", timeout=10)["step"] > step


def test_delete_and_shutdown_end_the_engine_processes(tmp_path: Path) -> None:
    live = LiveServer(make_settings(tmp_path / "data"), DefaultEngine()).start()
    try:
        with live.client() as api:
            a, b = (api.post("/v1/sessions", json=SMALL).json()["id"] for _ in range(2))
            pid_a, pid_b = engine_pid(live, a), engine_pid(live, b)
            assert api.delete(f"/v1/sessions/{a}").status_code == 204
            assert not running(pid_a) and running(pid_b)
    finally:
        live.stop()
    assert not running(pid_b)


def test_shutdown_with_a_dead_engine_keeps_the_session(tmp_path: Path) -> None:
    settings = make_settings(tmp_path / "data")
    live = LiveServer(settings, DefaultEngine()).start()
    try:
        with live.client() as api:
            sid = api.post("/v1/sessions", json=SMALL).json()["id"]
            assert api.post(f"/v1/sessions/{sid}/step", json={"n": 3}).status_code == 200
            pid = engine_pid(live, sid)
            os.kill(pid, signal.SIGKILL)
            assert_ended([pid])
    finally:
        live.stop()  # its checkpoint fails; the journal has the steps
    again = LiveServer(settings, DefaultEngine()).start()
    try:
        with again.client() as api:
            assert api.get(f"/v1/sessions/{sid}").json()["step"] == 3
            r = api.post(f"/v1/sessions/{sid}/step")
            assert r.status_code == 200 and r.json()["step"] == 4, r.text
    finally:
        again.stop()


def test_a_control_overtakes_the_queued_steps_and_the_replies_tell_the_order() -> None:
    """Pipelined requests: a control sent after four queued steps runs before the steps still
    waiting; the replies come in the order the engine ran them, with the step the control
    applied after, and the frames after it carry its control id."""
    sim = RemoteSim("pipelined")
    try:
        sim.call(ops.create, DefaultEngine(), builtin_scene("default").on_uniform_grid((5, 5, 9)))
        sub = Subscription(fields=("temperature",))
        steps = [sim.submit(ops.step_frames, (sub,), "s", 0) for _ in range(4)]
        control = sim.submit(ops.apply_control, "active", {"power_w": 20.0}, 0, urgent=True)
        assert sim.in_flight == 5
        order = [sim.receive() for _ in range(5)]
        assert sim.in_flight == 0 and sorted(r.id for r in order) == sorted([*steps, control])
        at = next(i for i, r in enumerate(order) if r.id == control)
        assert at < 4, "the control waited behind every queued step"
        assert order[at].ok and order[at].value == (1, at)  # control id 1, after step `at`
        frames = [unpack(r.value[1][sub].to_bytes(0)) for r in order if r.id != control]
        assert [f["step"] for f in frames] == [1, 2, 3, 4] and sim.step_index == 4
        assert [f["control_id"] for f in frames] == [0] * at + [1] * (4 - at)
        with pytest.raises(NotFoundError):  # errors still come back to the caller
            sim.call(ops.apply_control, "nope", {"power_w": 1.0}, 0)
    finally:
        sim.close()
