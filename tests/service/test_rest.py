"""The REST API against a live uvicorn server: lifecycle, fields, errors, limits, auth."""

from __future__ import annotations

import io
import threading

import httpx
import numpy as np
import pytest

from diathermy.service.encoding import decode_array, unpack
from tests.service.conftest import CUT, SMALL, TOKEN_B, LiveServer, step_until_cut


def test_lifecycle(api: httpx.Client) -> None:
    r = api.post("/v1/sessions", json=SMALL)
    assert r.status_code == 201, r.text
    s = r.json()
    assert s["grid"]["shape"] == [5, 5, 9] and s["step"] == 0
    assert s["effects"] == ["electric", "thermal", "vaporization", "mechanics", "dissection"]
    # V = 0 and u = 0 on the 5x9 bottom nodes; T and phi live on all 225 nodes
    assert s["dof_counts"] == {
        "potential": 225 - 45,
        "temperature": 225,
        "displacement": 3 * (225 - 45),
        "level_set": 225,
    }
    sid = s["id"]
    assert [x["id"] for x in api.get("/v1/sessions").json()["sessions"]] == [sid]

    r = api.post(f"/v1/sessions/{sid}/step", json={"n": 3})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["step"] == 3 and len(body["reports"]) == 3
    assert body["reports"][0]["delivered_power_w"] == pytest.approx(50.0)
    assert body["reports"][0]["effects"]["electric"]["ran"] is True
    got = api.get(f"/v1/sessions/{sid}").json()
    assert got["step"] == 3 and got["time_s"] == pytest.approx(0.09)
    assert got["last_report"]["step"] == 3
    heated = body["reports"][-1]["energy"]["joule_in"]
    assert heated > 0

    r = api.patch(f"/v1/sessions/{sid}/electrodes/active", json={"power_w": 0.0})
    assert r.status_code == 200 and r.json()["control_id"] == 1
    rep = api.post(f"/v1/sessions/{sid}/step", json={}).json()["reports"][0]
    assert rep["delivered_power_w"] == 0.0 and rep["energy"]["joule_in"] == heated  # no heating
    electric = rep["effects"]["electric"]
    assert electric["ran"] is False
    assert electric["reason"].startswith("no active electrode in contact with the tissue")

    api.patch(f"/v1/sessions/{sid}/electrodes/active", json={"power_w": 20.0})
    rep = api.post(f"/v1/sessions/{sid}/step").json()["reports"][0]
    assert rep["delivered_power_w"] == pytest.approx(20.0)  # the new drive is what is delivered

    assert api.delete(f"/v1/sessions/{sid}").status_code == 204
    assert api.get(f"/v1/sessions/{sid}").status_code == 404
    assert api.get("/v1/sessions").json()["sessions"] == []


def test_fields_surface_vtu(api: httpx.Client) -> None:
    sid = api.post("/v1/sessions", json=CUT).json()["id"]
    assert api.get(f"/v1/sessions/{sid}/surface").json()["faces"] == []  # nothing cut yet
    step = step_until_cut(api, sid)
    r = api.get(f"/v1/sessions/{sid}/fields", params={"fields": "temperature,displacement"})
    assert r.status_code == 200 and r.headers["content-type"] == "application/msgpack"
    msg = unpack(r.content)
    t = decode_array(msg["fields"]["temperature"])
    assert t.shape == (5, 5, 9) and t.dtype == np.float32 and t.max() > 373.15  # boiling
    u = decode_array(msg["fields"]["displacement"])
    assert u.shape == (5, 5, 9, 3) and np.abs(u).max() > 0  # pore pressure deforms the block
    assert msg["step"] == step and msg["grid"]["shape"] == [5, 5, 9]

    r = api.get(
        f"/v1/sessions/{sid}/fields",
        params={"fields": "temperature,joule_heat", "format": "npz", "dtype": "float64"},
    )
    npz = np.load(io.BytesIO(r.content))
    assert npz["temperature"].dtype == np.float64 and npz["joule_heat"].shape == (6 * 4 * 4 * 8,)
    assert int(npz["step"]) == step
    np.testing.assert_allclose(npz["temperature"], t, rtol=1e-6)  # same state, both formats

    surf = api.get(f"/v1/sessions/{sid}/surface").json()
    verts, faces = np.array(surf["vertices_m"]), np.array(surf["faces"])
    assert len(faces) > 0 and faces.max() < len(verts)
    # the crater lies under the electrode, inside the block
    assert np.all((verts >= -1e-12) & (verts <= np.array([0.02, 0.01, 0.01]) + 1e-12))
    assert verts[:, 2].min() < 0.01
    m = unpack(api.get(f"/v1/sessions/{sid}/surface", params={"format": "msgpack"}).content)
    assert decode_array(m["faces"]).shape == faces.shape
    np.testing.assert_allclose(decode_array(m["vertices_m"]), verts)

    r = api.get(f"/v1/sessions/{sid}/vtu")
    assert r.status_code == 200 and b"<VTKFile" in r.content
    assert b'Name="temperature"' in r.content and b'Name="level_set"' in r.content


def fields64(api: httpx.Client, sid: str, names: str) -> dict[str, np.ndarray]:
    r = api.get(f"/v1/sessions/{sid}/fields", params={"fields": names, "dtype": "float64"})
    return {k: decode_array(v) for k, v in unpack(r.content)["fields"].items()}


def test_snapshot_and_restore(api: httpx.Client) -> None:
    sid = api.post("/v1/sessions", json=SMALL).json()["id"]
    api.post(f"/v1/sessions/{sid}/step", json={"n": 2})
    snap = api.post(f"/v1/sessions/{sid}/snapshots").json()
    assert snap["step"] == 2
    at_snapshot = fields64(api, sid, "temperature,potential")
    api.post(f"/v1/sessions/{sid}/step", json={"n": 1})
    after_one = fields64(api, sid, "temperature,potential")
    api.post(f"/v1/sessions/{sid}/step", json={"n": 3})
    r = api.post(f"/v1/sessions/{sid}/snapshots/{snap['id']}/restore")
    assert r.status_code == 200 and r.json()["step"] == 2
    assert r.json()["time_s"] == pytest.approx(0.06)
    for name, value in fields64(api, sid, "temperature,potential").items():
        np.testing.assert_array_equal(value, at_snapshot[name])
    api.post(f"/v1/sessions/{sid}/step", json={"n": 1})  # the restored run repeats bit for bit
    for name, value in fields64(api, sid, "temperature,potential").items():
        np.testing.assert_array_equal(value, after_one[name])
    assert [s["id"] for s in api.get(f"/v1/sessions/{sid}/snapshots").json()] == [snap["id"]]
    assert api.post(f"/v1/sessions/{sid}/snapshots/nope/restore").json()["field"] == "snapshot_id"


@pytest.mark.parametrize(
    ("body", "status", "field"),
    [
        ({"builtin": "nope"}, 422, "builtin"),
        ({}, 422, "body"),
        ({"builtin": "default", "grid": [2, 5, 9]}, 422, "grid"),
        ({"builtin": "default", "grid": [33, 33, 65]}, 422, "scene.grid"),
        ({"scene": {"grid": [5, 5, 9], "dt_s": -1}}, 422, "body.scene.dt_s"),
        ({"scene": {"grid": [5, 5, 9], "bogus": 1}}, 422, "body.scene.bogus"),
    ],
)
def test_bad_create_names_the_field(api: httpx.Client, body: dict, status: int, field: str) -> None:
    r = api.post("/v1/sessions", json=body)
    assert r.status_code == status, r.text
    err = r.json()
    assert err["field"].startswith(field) or field in err["message"], err
    assert "Traceback" not in r.text


def test_grid_limit_reports_estimated_memory(api: httpx.Client) -> None:
    r = api.post("/v1/sessions", json={"builtin": "default", "grid": [33, 33, 65]})
    assert r.status_code == 422 and r.json()["error"] == "limit_exceeded"
    assert "70785 nodes" in r.json()["message"] and "MiB" in r.json()["message"]


def test_limits_steps_sessions_and_body_size(api: httpx.Client) -> None:
    sid = api.post("/v1/sessions", json=SMALL).json()["id"]
    r = api.post(f"/v1/sessions/{sid}/step", json={"n": 51})
    assert r.status_code == 422 and r.json()["field"] == "n"
    assert api.post(f"/v1/sessions/{sid}/step", json={"n": 0}).json()["field"] == "body.n"
    for _ in range(3):
        assert api.post("/v1/sessions", json=SMALL).status_code == 201
    r = api.post("/v1/sessions", json=SMALL)
    assert r.status_code == 429 and r.json()["error"] == "too_many_sessions"
    r = api.post(
        "/v1/sessions",
        content=b"{" + b" " * 300_000 + b"}",
        headers={"content-type": "application/json"},
    )
    assert r.status_code == 413 and r.json()["error"] == "too_large"


def test_bad_reads_are_4xx(api: httpx.Client) -> None:
    sid = api.post("/v1/sessions", json=SMALL).json()["id"]
    r = api.get(f"/v1/sessions/{sid}/fields", params={"fields": "temperature,nope"})
    assert r.status_code == 400 and r.json()["field"] == "fields" and "nope" in r.json()["message"]
    r = api.get(f"/v1/sessions/{sid}/fields", params={"fields": "temperature", "dtype": "int8"})
    assert r.status_code == 422 and r.json()["field"] == "query.dtype"
    r = api.patch(f"/v1/sessions/{sid}/electrodes/ghost", json={"power_w": 1})
    assert r.status_code == 404 and r.json()["field"] == "name"  # a missing resource
    r = api.patch(f"/v1/sessions/{sid}/electrodes/active", json={"power_w": -1})
    assert r.status_code == 422 and r.json()["field"] == "body.power_w"
    assert api.get("/v1/nothing").json()["error"] == "not_found"


def test_auth_and_isolation(live: LiveServer, api: httpx.Client) -> None:
    sid = api.post("/v1/sessions", json=SMALL).json()["id"]
    with live.client(None) as anon, live.client("wrong") as wrong, live.client(TOKEN_B) as other:
        assert anon.get("/v1/sessions").status_code == 401
        r = wrong.get("/v1/sessions")
        assert r.status_code == 401 and r.headers["www-authenticate"] == "Bearer"
        assert other.get("/v1/sessions").json()["sessions"] == []
        for method, path in [
            ("GET", f"/v1/sessions/{sid}"),
            ("POST", f"/v1/sessions/{sid}/step"),
            ("GET", f"/v1/sessions/{sid}/fields?fields=temperature"),
            ("DELETE", f"/v1/sessions/{sid}"),
        ]:
            assert other.request(method, path).status_code == 404
    assert api.get(f"/v1/sessions/{sid}").status_code == 200
    owner = live.state.registry.sessions[sid].meta["owner"]
    assert len(owner) == 64 and "token" not in owner  # a sha256, never the token


def test_concurrent_step_gets_409_and_other_sessions_proceed(
    live: LiveServer, api: httpx.Client
) -> None:
    slow = api.post("/v1/sessions", json=CUT).json()["id"]  # boiling and cutting: seconds
    fast = api.post("/v1/sessions", json=SMALL).json()["id"]
    api.post(f"/v1/sessions/{fast}/step")  # its solver set-up is done before the race
    results: list[httpx.Response] = []
    t = threading.Thread(
        target=lambda: results.append(api.post(f"/v1/sessions/{slow}/step", json={"n": 15}))
    )
    t.start()
    deadline = 500  # up to 10 s for the step to take the lock on a loaded machine
    while not live.state.registry.sessions[slow].lock.locked() and deadline:
        threading.Event().wait(0.02)
        deadline -= 1
    with live.client() as c2:
        r = c2.post(f"/v1/sessions/{slow}/step")
        assert r.status_code == 409 and r.json()["error"] == "busy"
        r = c2.post(f"/v1/sessions/{fast}/step")  # another session is not blocked
        assert r.status_code == 200
        fast_s = r.elapsed.total_seconds()
        health_s = c2.get("/healthz").elapsed.total_seconds()
        still_busy = live.state.registry.sessions[slow].lock.locked()
    t.join()
    assert [r.status_code for r in results] == [200]
    slow_s = results[0].elapsed.total_seconds()
    assert still_busy or max(fast_s, health_s) < slow_s / 2, (fast_s, health_s, slow_s)


def test_health_ready_metrics(live: LiveServer, api: httpx.Client) -> None:
    assert httpx.get(live.url + "/healthz").json()["status"] == "ok"
    assert httpx.get(live.url + "/readyz").json() == {"status": "ok", "sessions": 0}
    sid = api.post("/v1/sessions", json=SMALL).json()["id"]
    api.post(f"/v1/sessions/{sid}/step", json={"n": 2})
    text = httpx.get(live.url + "/metrics").text
    assert 'diathermy_effect_seconds_count{effect="thermal"} 2.0' in text
    assert "diathermy_sessions 1.0" in text
    assert "diathermy_stream_frames_dropped_total" in text
