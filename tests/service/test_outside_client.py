"""What an outside client tripped on (issue 23), each against a live server."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from websockets.exceptions import ConnectionClosed

from diathermy.service.encoding import unpack
from diathermy.service.engine import DefaultEngine
from diathermy.service.routes.fields import FIELD_NAMES
from tests.service.conftest import SMALL, LiveServer, make_settings
from tests.service.test_stream import metric_values, open_stream, recv, recv_type

ROOT = Path(__file__).resolve().parents[2]


def test_snapshot_after_steps_then_crash_reports_the_step_it_holds(tmp_path: Path) -> None:
    data = tmp_path / "data"
    first = LiveServer(make_settings(data), DefaultEngine()).start()
    try:
        with first.client() as api:
            sid = api.post("/v1/sessions", json=SMALL).json()["id"]
            api.post(f"/v1/sessions/{sid}/step", json={"n": 10})
            assert api.get(f"/v1/sessions/{sid}").json()["step"] == 10
            assert api.post(f"/v1/sessions/{sid}/snapshots").status_code == 201
        # a second server on the same data dir while the first never shut down (a crash)
        second = LiveServer(make_settings(data), DefaultEngine()).start()
        try:
            with second.client() as api:
                listed = api.get("/v1/sessions").json()["sessions"][0]
                got = api.get(f"/v1/sessions/{sid}").json()
                fields = api.get(f"/v1/sessions/{sid}/fields", params={"fields": "temperature"})
                held = unpack(fields.content)["step"]
                assert listed["step"] == got["step"] == held == 10
                assert api.get(f"/v1/sessions/{sid}").json()["step"] == 10  # loading kept it
        finally:
            second.stop()
    finally:
        first.stop()


def test_delete_while_streaming_closes_the_stream(live: LiveServer, api: httpx.Client) -> None:
    sid = api.post("/v1/sessions", json=SMALL).json()["id"]
    with open_stream(live, sid) as ws:
        recv(ws)
        ws.send(json.dumps({"type": "run", "rate_hz": 50}))
        recv_type(ws, "frame")
        assert metric_values(httpx.get(live.url + "/metrics").text)["diathermy_stream_clients"] == 1
        assert api.delete(f"/v1/sessions/{sid}").status_code == 204
        err = recv_type(ws, "error")
        assert err["error"] == "not_found" and err["field"] == "session_id"
        with pytest.raises(ConnectionClosed) as info:
            while True:
                recv(ws)
        assert info.value.rcvd is not None and info.value.rcvd.code == 4404
    values = metric_values(httpx.get(live.url + "/metrics").text)
    assert values["diathermy_stream_clients"] == 0
    assert values["diathermy_sessions"] == values["diathermy_sessions_loaded"] == 0


def test_loaded_sessions_gauge_follows_creates_deletes_and_loads(tmp_path: Path) -> None:
    data = tmp_path / "data"
    first = LiveServer(make_settings(data), DefaultEngine()).start()
    try:
        with first.client() as api:
            ids = [api.post("/v1/sessions", json=SMALL).json()["id"] for _ in range(3)]
            gauge = lambda: metric_values(api.get("/metrics").text)["diathermy_sessions_loaded"]  # noqa: E731
            assert gauge() == 3
            api.delete(f"/v1/sessions/{ids[0]}")
            assert gauge() == 2
    finally:
        first.stop()
    second = LiveServer(make_settings(data), DefaultEngine()).start()
    try:
        with second.client() as api:
            values = metric_values(api.get("/metrics").text)
            assert values["diathermy_sessions"] == 2 and values["diathermy_sessions_loaded"] == 0
            api.post(f"/v1/sessions/{ids[1]}/step")
            assert metric_values(api.get("/metrics").text)["diathermy_sessions_loaded"] == 1
            for sid in ids[1:]:
                api.delete(f"/v1/sessions/{sid}")
            values = metric_values(api.get("/metrics").text)
            assert values["diathermy_sessions"] == values["diathermy_sessions_loaded"] == 0
    finally:
        second.stop()


def chunks(total: int, size: int = 8192) -> Iterator[bytes]:
    """A JSON body sent chunked (no Content-Length): a scene name padded to ``total`` bytes."""
    body = json.dumps({"builtin": "default", "grid": [5, 5, 9], "pad": "x" * total}).encode()
    for i in range(0, len(body), size):
        yield body[i : i + size]


def test_chunked_body_over_the_limit_is_413(live: LiveServer, api: httpx.Client) -> None:
    limit = live.settings.max_request_bytes
    r = api.post("/v1/sessions", content=chunks(2 * limit))
    assert r.status_code == 413 and r.json()["error"] == "too_large" and r.json()["field"] == "body"
    r = api.post("/v1/sessions", content=chunks(100))  # under the limit: parsed, then refused
    assert r.status_code == 422 and r.json()["error"] == "validation_error"
    r = api.post("/v1/sessions", content=b"{not json")  # a broken body: a documented code
    assert r.status_code == 422 and r.json()["error"] == "validation_error"


def test_electrode_drive_is_range_checked_when_it_arrives(
    live: LiveServer, api: httpx.Client
) -> None:
    sid = api.post("/v1/sessions", json=SMALL).json()["id"]
    for change, field in [
        ({"power_w": 1e300}, "body.power_w"),
        ({"current_density_a_per_m2": 1e30}, "body.current_density_a_per_m2"),
        ({"power_w": False}, "body.power_w"),  # a bool is not a number (found by schemathesis)
        ({"power_w": "30"}, "body.power_w"),
        ({"position_m": [True, 0.0]}, "body.position_m.0"),
        ({"active": 1}, "body.active"),
    ]:
        r = api.patch(f"/v1/sessions/{sid}/electrodes/active", json=change)
        assert r.status_code == 422 and r.json()["field"] == field, r.text
    assert api.post(f"/v1/sessions/{sid}/step").status_code == 200  # nothing was applied
    assert api.patch(f"/v1/sessions/{sid}/electrodes/active", json={"power_w": 1000}).is_success
    rep = api.post(f"/v1/sessions/{sid}/step", json={"n": 3}).json()["reports"][-1]
    assert rep["delivered_power_w"] == pytest.approx(1000.0)  # the top of the range still steps
    scene = {"scene": {"grid": [5, 5, 9], "electrodes": [{"power_w": 1e300}]}}
    r = api.post("/v1/sessions", json=scene)
    assert r.status_code == 422 and r.json()["field"] == "scene.electrodes.0.power_w", r.text
    with open_stream(live, sid) as ws:
        recv(ws)
        ws.send(json.dumps({"type": "electrode", "power_w": 1e300}))
        err = recv_type(ws, "error")
        assert err["error"] == "bad_message" and err["field"] == "electrode.power_w"
    with open_stream(live, sid) as ws:  # a bad message closes the stream: a new one
        recv(ws)
        ws.send(json.dumps({"type": "electrode", "power_w": True}))
        err = recv_type(ws, "error")
        assert err["error"] == "bad_message" and err["field"] == "electrode.power_w"


def test_stream_steps_have_the_rest_limit(live: LiveServer, api: httpx.Client) -> None:
    sid = api.post("/v1/sessions", json=SMALL).json()["id"]
    limit = live.settings.max_steps_per_request
    assert api.post(f"/v1/sessions/{sid}/step", json={"n": limit + 1}).status_code == 422
    with open_stream(live, sid) as ws:
        recv(ws)
        ws.send(json.dumps({"type": "step", "n": limit + 1}))
        err = recv_type(ws, "error")
        assert err["error"] == "limit_exceeded" and err["field"] == "n"
        ws.send(json.dumps({"type": "step", "n": 1}))  # the stream stays open
        assert recv_type(ws, "ack")["of"] == "step"


def test_warnings_are_json_log_lines() -> None:
    code = (
        "from diathermy.service.jsonlog import configure_logging\n"
        "import numpy as np\n"
        "configure_logging('INFO')\n"
        "np.array([1e308]) * 10\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT / "server"), "PYTHONWARNINGS": "default"}
    proc = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60
    )
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert lines, "the overflow should have warned"
    records = [json.loads(ln) for ln in lines]  # every line is one JSON object
    assert any(
        r["logger"] == "py.warnings" and "RuntimeWarning" in r["message"] for r in records
    ), records


def test_method_not_allowed_lists_every_method(live: LiveServer, api: httpx.Client) -> None:
    sid = api.post("/v1/sessions", json=SMALL).json()["id"]
    r = api.options(f"/v1/sessions/{sid}")
    assert r.status_code == 405 and r.json()["error"] == "method_not_allowed"
    assert r.headers["allow"] == "DELETE, GET"
    r = api.put("/v1/sessions")
    assert r.status_code == 405 and r.headers["allow"] == "GET, POST"


def test_served_openapi_is_the_committed_one(live: LiveServer) -> None:
    served = httpx.get(live.url + "/openapi.json").json()
    committed = json.loads((ROOT / "openapi" / "openapi.json").read_text())
    assert served == committed
    accuracy = committed["paths"]["/v1/accuracy-cost"]["get"]["responses"]
    assert "401" in accuracy


def test_documented_field_names_are_the_sessions(api: httpx.Client) -> None:
    sid = api.post("/v1/sessions", json=SMALL).json()["id"]
    r = api.get(f"/v1/sessions/{sid}/fields", params={"fields": ",".join(FIELD_NAMES)})
    assert r.status_code == 200
    assert list(unpack(r.content)["fields"]) == list(FIELD_NAMES)
    r = api.get(f"/v1/sessions/{sid}/fields", params={"fields": "nope"})
    assert r.json()["message"].endswith("available: " + ", ".join(FIELD_NAMES))
