"""The WebSocket stream against a live server with a real ``websockets`` client."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from prometheus_client.parser import text_string_to_metric_families
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

from diathermy.service.encoding import decode_array, pack, unpack
from diathermy.service.engine import DefaultEngine
from tests.service.conftest import (
    CUT,
    SMALL,
    TOKEN_A,
    TOKEN_B,
    LiveServer,
    make_settings,
    step_until_cut,
)
from tests.service.rawws import RawWebSocket


def metric_values(text: str) -> dict[str, float]:
    """Unlabelled samples of a Prometheus exposition."""
    return {
        s.name: s.value
        for fam in text_string_to_metric_families(text)
        for s in fam.samples
        if not s.labels
    }


def open_stream(live: LiveServer, sid: str, token: str = TOKEN_A, **kw: Any) -> ClientConnection:
    return connect(
        f"{live.ws_url}/v1/sessions/{sid}/stream",
        additional_headers={"Authorization": f"Bearer {token}"},
        open_timeout=10,
        **kw,
    )


def recv(ws: ClientConnection, timeout: float = 5.0) -> dict[str, Any]:
    data = ws.recv(timeout=timeout)
    assert isinstance(data, bytes)
    return unpack(data)


def recv_type(ws: ClientConnection, kind: str, timeout: float = 5.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while True:
        msg = recv(ws, max(0.01, deadline - time.monotonic()))
        if msg["type"] == kind:
            return msg


def frames(ws: ClientConnection, n: int, timeout: float = 5.0) -> Iterator[dict[str, Any]]:
    for _ in range(n):
        yield recv_type(ws, "frame", timeout)


@pytest.fixture()
def sid(api: httpx.Client) -> str:
    return api.post("/v1/sessions", json=SMALL).json()["id"]


def test_subscribe_run_and_control(live: LiveServer, sid: str) -> None:
    with open_stream(live, sid) as ws:
        hello = recv(ws)
        assert hello["type"] == "hello" and hello["step"] == 0 and "temperature" in hello["fields"]
        ws.send(json.dumps({"type": "subscribe", "fields": ["temperature"], "dtype": "float16"}))
        first = recv_type(ws, "frame")  # the current state comes at once
        t = decode_array(first["fields"]["temperature"])
        assert first["step"] == 0 and t.shape == (5, 5, 9) and t.dtype == np.float16
        ws.send(json.dumps({"type": "run", "rate_hz": 100}))
        steps = [f["step"] for f in frames(ws, 5)]
        assert steps == sorted(steps) and steps[-1] >= 5
        assert all(f["report"]["delivered_power_w"] == pytest.approx(50.0) for f in frames(ws, 2))

        ws.send(pack({"type": "electrode", "power_w": 0.0, "tag": "off"}))  # msgpack works too
        ack = recv_type(ws, "ack")
        assert ack["of"] == "electrode" and ack["tag"] == "off" and ack["running"]
        after = next(f for f in frames(ws, 50) if f["control_id"] >= ack["control_id"])
        assert after["report"]["delivered_power_w"] == 0.0
        hot = decode_array(after["fields"]["temperature"]).astype(float)
        later = next(frames(ws, 1))
        assert later["step"] > after["step"]
        # no heating: no Joule energy enters, and heat only spreads and leaves (max principle)
        assert later["report"]["energy"]["joule_in"] == after["report"]["energy"]["joule_in"]
        assert decode_array(later["fields"]["temperature"]).max() <= hot.max()

        ws.send(json.dumps({"type": "pause"}))
        paused_at = recv_type(ws, "ack")["control_id"]
        assert paused_at == ack["control_id"]
        with pytest.raises(TimeoutError):  # drain what was in flight, then silence
            while True:
                recv_type(ws, "frame", timeout=0.3)
        ws.send(json.dumps({"type": "step", "n": 2}))
        a, b = frames(ws, 2)
        assert b["step"] == a["step"] + 1


def test_every_kth_and_surface_region(live: LiveServer, api: httpx.Client) -> None:
    sid = api.post("/v1/sessions", json=CUT).json()["id"]
    start = step_until_cut(api, sid)
    with open_stream(live, sid) as ws:
        recv(ws)
        ws.send(
            json.dumps(
                {
                    "type": "subscribe",
                    "fields": ["temperature", "displacement"],
                    "every": 3,
                    "region": "surface",
                }
            )
        )
        now = recv_type(ws, "frame", timeout=10)  # the current state, whatever its step
        assert now["step"] == start
        ws.send(json.dumps({"type": "step", "n": 6}))
        got = list(frames(ws, 2, timeout=20))
        due = [s for s in range(start + 1, start + 7) if s % 3 == 0]
        assert [f["step"] for f in got] == due
        surf = got[-1]["surface"]
        verts = decode_array(surf["vertices"])
        faces = decode_array(surf["faces"])
        n = len(verts)
        assert n > 0 and verts.shape == (n, 3) and faces.dtype == np.int32
        assert faces.max() < n
        assert decode_array(got[-1]["fields"]["displacement"]).shape == (n, 3)
        t = decode_array(got[-1]["fields"]["temperature"])
        assert t.shape == (n,) and t.min() > 300.0  # sampled tissue temperatures, in K


def test_top_region_is_the_volume_top_layer(live: LiveServer, api: httpx.Client) -> None:
    """The tissue's top face only: the volume frame's last z layer, the same values in the same
    dtype, in about 1/nz of the bytes (what a viewer that draws the top face needs)."""
    sid = api.post("/v1/sessions", json=CUT).json()["id"]
    step_until_cut(api, sid)
    got: dict[str, tuple[int, dict]] = {}
    with open_stream(live, sid) as ws:
        recv(ws)
        for region in ("volume", "top"):
            sub = {"fields": ["temperature", "displacement", "level_set"], "dtype": "float16"}
            ws.send(json.dumps({"type": "subscribe", "region": region, **sub}))
            while True:
                raw = ws.recv(timeout=10)
                msg = unpack(raw)
                if msg["type"] == "frame":
                    break
            got[region] = (len(raw), msg)
    (vol_bytes, vol), (top_bytes, top) = got["volume"], got["top"]
    assert vol["step"] == top["step"]
    nz = decode_array(vol["fields"]["temperature"]).shape[0]
    for name in ("temperature", "displacement", "level_set"):
        whole, face = decode_array(vol["fields"][name]), decode_array(top["fields"][name])
        assert face.dtype == np.float16 and np.array_equal(face, whole[-1]), name
    assert decode_array(top["fields"]["level_set"]).min() < 0  # the cut reaches the face

    def data_bytes(msg: dict) -> int:
        return sum(len(a["data"]) for a in msg["fields"].values())

    assert nz * data_bytes(top) == data_bytes(vol)  # the arrays: exactly 1/nz
    assert top_bytes < vol_bytes - (1 - 1 / nz) * data_bytes(vol) + 64  # the rest: the header
    with open_stream(live, sid) as ws:
        recv(ws)
        ws.send(json.dumps({"type": "subscribe", "fields": ["joule_heat"], "region": "top"}))
        err = recv_type(ws, "error")
        assert err["field"] == "fields.0" and "top region" in err["message"]


@pytest.mark.parametrize(
    ("message", "field"),
    [
        ("not json at all", None),
        (json.dumps({"type": "warp"}), ""),
        (json.dumps({"type": "run", "rate_hz": -5}), "run.rate_hz"),
        (json.dumps({"type": "subscribe", "every": 0}), "subscribe.every"),
        (json.dumps([1, 2, 3]), ""),
    ],
)
def test_bad_messages_close_4400(
    live: LiveServer, sid: str, message: str, field: str | None
) -> None:
    with open_stream(live, sid) as ws:
        recv(ws)
        ws.send(message)
        err = recv_type(ws, "error")
        assert err["error"] == "bad_message"
        with pytest.raises(ConnectionClosed) as info:
            recv(ws)
        assert info.value.rcvd is not None and info.value.rcvd.code == 4400
        reason = json.loads(info.value.rcvd.reason)
        assert reason["error"] == "bad_message"
        if field:
            assert field in (reason["field"] or "") or field in err["message"]
    with open_stream(live, sid) as ws:  # the server is fine afterwards
        assert recv(ws)["type"] == "hello"


def test_rejected_values_keep_the_stream_open(live: LiveServer, sid: str) -> None:
    with open_stream(live, sid) as ws:
        recv(ws)
        ws.send(json.dumps({"type": "electrode", "name": "ghost", "power_w": 1}))
        assert recv_type(ws, "error")["field"] == "name"
        ws.send(json.dumps({"type": "subscribe", "fields": ["joule_heat"], "region": "surface"}))
        assert recv_type(ws, "error")["field"] == "fields.0"
        ws.send(json.dumps({"type": "subscribe", "fields": ["nope"]}))
        assert recv_type(ws, "error")["field"] == "fields.0"
        ws.send(json.dumps({"type": "step"}))
        assert recv_type(ws, "ack")["of"] == "step"
        ws.send("x" * 10_000)  # over max_message_bytes
        with pytest.raises(ConnectionClosed) as info:
            while True:
                recv(ws)
        assert info.value.rcvd is not None and info.value.rcvd.code == 1009


def test_stream_auth(live: LiveServer, sid: str) -> None:
    for token, code, error in [("wrong", 4401, "unauthorized"), (TOKEN_B, 4404, "not_found")]:
        with open_stream(live, sid, token=token) as ws:
            msg = recv(ws)  # an error message comes before the close, as for every close
            assert msg["type"] == "error" and msg["error"] == error
            with pytest.raises(ConnectionClosed) as info:
                recv(ws)
        assert info.value.rcvd is not None and info.value.rcvd.code == code
        assert json.loads(info.value.rcvd.reason)["error"] == error
    with connect(f"{live.ws_url}/v1/sessions/{sid}/stream?token={TOKEN_A}") as ws:
        assert recv(ws)["type"] == "hello"


def test_slow_client_coalesces_frames(tmp_path: Path) -> None:
    live = LiveServer(
        make_settings(tmp_path / "data", max_grid_nodes=20_000, max_stream_rate_hz=1000.0),
        DefaultEngine(),
    ).start()
    try:
        with live.client() as api:
            body = {"builtin": "default", "grid": [17, 17, 33]}
            sid = api.post("/v1/sessions", json=body).json()["id"]
        ws = RawWebSocket("127.0.0.1", live.settings.port, f"/v1/sessions/{sid}/stream", TOKEN_A)
        try:
            assert ws.recv()["type"] == "hello"
            ws.send_text(
                json.dumps({"type": "subscribe", "fields": ["temperature", "displacement"]})
            )
            ws.send_text(json.dumps({"type": "run", "rate_hz": 1000}))
            time.sleep(2.0)  # a client that reads nothing: TCP pushes back on the server
            ws.send_text(json.dumps({"type": "pause"}))
            got = []
            with pytest.raises(TimeoutError):
                while True:
                    got.append(ws.recv(timeout=1.0))
        finally:
            ws.close()
        fr = [m for m in got if m["type"] == "frame"]
        steps = live.state.registry.sessions[sid].sim.step_index
        assert steps > 50  # the real engine steps this grid at ~60/s here; the client read ~30
        assert fr[-1]["step"] == steps  # the newest state always arrives
        assert fr[-1]["dropped"] > steps / 2  # most frames were coalesced away, not queued
        values = metric_values(httpx.get(live.url + "/metrics").text)
        dropped = values["diathermy_stream_frames_dropped_total"]
        sent = values["diathermy_stream_frames_sent_total"]
        assert dropped == fr[-1]["dropped"] and sent + dropped == steps + 1  # +1: subscribe frame
    finally:
        live.stop()
