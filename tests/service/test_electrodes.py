"""Reading electrodes back over REST (GET .../electrodes[/{name}]) against a live server: what
the scene, its path and schedule, PATCH and stream controls make of each electrode."""

from __future__ import annotations

import json

import httpx
import pytest
from websockets.sync.client import connect

from diathermy.engine.electrodes import path_position
from diathermy.scene import builtin_scene
from diathermy.service.encoding import unpack
from tests.service.conftest import CUT, SMALL, TOKEN_A, TOKEN_B, LiveServer


def one(api: httpx.Client, sid: str, name: str = "active") -> dict:
    r = api.get(f"/v1/sessions/{sid}/electrodes/{name}")
    assert r.status_code == 200, r.text
    return r.json()


def test_electrode_reads_back_scene_and_controls(live: LiveServer, api: httpx.Client) -> None:
    sid = api.post("/v1/sessions", json=SMALL).json()["id"]
    listed = api.get(f"/v1/sessions/{sid}/electrodes").json()["electrodes"]
    assert listed == [
        {
            "name": "active",
            "position_m": [0.1, 0.05],
            "radius_m": 0.00117,
            "drive": "power",
            "power_w": 50.0,
            "current_density_a_per_m2": 57200.0,
            "max_voltage_v": None,
            "active": True,
            "follows_path": False,
            "control_id": 0,
            "step": 0,
            "time_s": 0.0,
        }
    ]
    assert one(api, sid) == listed[0]

    ack = api.patch(
        f"/v1/sessions/{sid}/electrodes/active",
        json={"position_m": [0.05, 0.04], "power_w": 20.0, "active": False},
    ).json()
    e = one(api, sid)
    assert e["position_m"] == [0.05, 0.04] and e["power_w"] == 20.0 and e["active"] is False
    assert e["control_id"] == ack["control_id"] == 1

    api.patch(f"/v1/sessions/{sid}/electrodes/active", json={"current_density_a_per_m2": 1e4})
    api.post(f"/v1/sessions/{sid}/step", json={"n": 2})
    e = one(api, sid)
    assert e["drive"] == "current_density" and e["current_density_a_per_m2"] == 1e4
    assert e["position_m"] == [0.05, 0.04] and e["active"] is False  # earlier changes stay
    assert e["step"] == 2 and e["time_s"] == pytest.approx(0.06)

    # a control on the stream is read back the same way, once acknowledged
    with connect(
        f"{live.ws_url}/v1/sessions/{sid}/stream",
        additional_headers={"Authorization": f"Bearer {TOKEN_A}"},
        open_timeout=10,
    ) as ws:
        assert unpack(ws.recv(timeout=10))["type"] == "hello"
        ws.send(json.dumps({"type": "electrode", "position_m": [0.12, 0.03], "active": True}))
        while (msg := unpack(ws.recv(timeout=10)))["type"] != "ack":
            pass
    e = one(api, sid)
    assert e["position_m"] == [0.12, 0.03] and e["active"] is True
    assert e["control_id"] == msg["control_id"] == 3


def test_path_and_schedule_follow_the_session_time(api: httpx.Client) -> None:
    sid = api.post("/v1/sessions", json={"builtin": "moving-electrode", "grid": [5, 5, 9]}).json()[
        "id"
    ]
    path = builtin_scene("moving-electrode").electrodes[0].path
    assert path is not None
    e0 = one(api, sid)
    assert e0["follows_path"] is True and e0["position_m"] == pytest.approx([0.04, 0.05])
    api.post(f"/v1/sessions/{sid}/step", json={"n": 10})
    e1 = one(api, sid)
    assert e1["position_m"] == pytest.approx(list(path_position(path, e1["time_s"])))
    assert e1["position_m"][0] > 0.04 + 0.003  # 0.3 s at 12.35 mm/s along the path
    api.patch(f"/v1/sessions/{sid}/electrodes/active", json={"position_m": [0.1, 0.05]})
    api.post(f"/v1/sessions/{sid}/step", json={"n": 2})
    e2 = one(api, sid)
    assert e2["follows_path"] is False and e2["position_m"] == [0.1, 0.05]

    scene = {
        **CUT["scene"],
        "electrodes": [
            {"name": "a", "position_m": [0.005, 0.005], "schedule_s": [[0.0, 0.05]]},
            {"name": "b", "position_m": [0.015, 0.005], "active": False},
        ],
    }
    sid = api.post("/v1/sessions", json={"scene": scene}).json()["id"]
    states = api.get(f"/v1/sessions/{sid}/electrodes").json()["electrodes"]
    assert [(s["name"], s["active"]) for s in states] == [("a", True), ("b", False)]
    api.post(f"/v1/sessions/{sid}/step", json={"n": 2})  # t = 0.06 s: past a's schedule
    assert one(api, sid, "a")["active"] is False
    assert one(api, sid, "b")["position_m"] == [0.015, 0.005]


def test_electrode_errors_name_the_field(live: LiveServer, api: httpx.Client) -> None:
    sid = api.post("/v1/sessions", json=SMALL).json()["id"]
    r = api.get(f"/v1/sessions/{sid}/electrodes/nope")
    assert r.status_code == 404
    assert r.json() == {
        "error": "not_found",
        "message": "no electrode 'nope'; electrodes: active",
        "field": "name",
    }
    r = api.get(f"/v1/sessions/{sid}/electrodes/{'x' * 129}")
    assert r.status_code == 422 and r.json()["field"] == "path.name"
    assert api.get("/v1/sessions/missing/electrodes").status_code == 404
    with live.client(TOKEN_B) as other:
        assert other.get(f"/v1/sessions/{sid}/electrodes").status_code == 404
        assert other.get(f"/v1/sessions/{sid}/electrodes/active").status_code == 404
    with live.client(None) as anonymous:
        assert anonymous.get(f"/v1/sessions/{sid}/electrodes").status_code == 401


def test_the_generator_voltage_limit_is_set_and_lifted_live(
    live: LiveServer, api: httpx.Client
) -> None:
    """PATCH max_voltage_v holds the electrode at that voltage from the next step (the report
    says so and the power falls to V^2 / R), 0 lifts it, and a bad value is a 422 naming it."""
    sid = api.post("/v1/sessions", json=SMALL).json()["id"]
    free = api.post(f"/v1/sessions/{sid}/step").json()["reports"][-1]
    need = free["effects"]["electric"]["extra"]["voltage_v"]
    assert not free["effects"]["electric"]["extra"]["voltage_limited"]
    r = api.patch(f"/v1/sessions/{sid}/electrodes/active", json={"max_voltage_v": 0.5 * need})
    assert r.status_code == 200, r.text
    assert one(api, sid)["max_voltage_v"] == 0.5 * need
    held = api.post(f"/v1/sessions/{sid}/step").json()["reports"][-1]
    extra = held["effects"]["electric"]["extra"]
    assert extra["voltage_limited"] and extra["voltage_v"] == pytest.approx(0.5 * need, rel=1e-9)
    assert held["delivered_power_w"] < 0.3 * free["delivered_power_w"]
    api.patch(f"/v1/sessions/{sid}/electrodes/active", json={"max_voltage_v": 0})
    assert one(api, sid)["max_voltage_v"] is None
    lifted = api.post(f"/v1/sessions/{sid}/step").json()["reports"][-1]
    assert not lifted["effects"]["electric"]["extra"]["voltage_limited"]
    with connect(
        f"{live.ws_url}/v1/sessions/{sid}/stream",
        additional_headers={"Authorization": f"Bearer {TOKEN_A}"},
        open_timeout=10,
    ) as ws:  # the same from a stream control, read back once acknowledged
        assert unpack(ws.recv(timeout=10))["type"] == "hello"
        ws.send(json.dumps({"type": "electrode", "max_voltage_v": 90.0}))
        while unpack(ws.recv(timeout=10))["type"] != "ack":
            pass
    assert one(api, sid)["max_voltage_v"] == 90.0
    for bad in (-1, 1e9, "x"):
        r = api.patch(f"/v1/sessions/{sid}/electrodes/active", json={"max_voltage_v": bad})
        assert r.status_code == 422 and "max_voltage_v" in r.json()["field"], r.text
    bad_scene = {
        **CUT["scene"],
        "electrodes": [{"position_m": [0.01, 0.005], "max_voltage_v": 1e9}],
    }
    r = api.post("/v1/sessions", json={"scene": bad_scene})
    assert r.status_code == 422 and r.json()["field"] == "scene.electrodes.0.max_voltage_v"
