"""Sessions survive a server restart: same id, owner, step and time, state restored lazily."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from diathermy.service.encoding import decode_array, unpack
from diathermy.service.engine import DefaultEngine
from tests.service.conftest import SMALL, TOKEN_B, LiveServer, make_settings


def temperature(api, sid: str) -> np.ndarray:  # noqa: ANN001
    r = api.get(f"/v1/sessions/{sid}/fields", params={"fields": "temperature", "dtype": "float64"})
    return decode_array(unpack(r.content)["fields"]["temperature"])


def test_restart_restores_sessions(tmp_path: Path) -> None:
    data = tmp_path / "data"
    first = LiveServer(make_settings(data), DefaultEngine()).start()
    try:
        with first.client() as api:
            sid = api.post("/v1/sessions", json=SMALL).json()["id"]
            api.post(f"/v1/sessions/{sid}/step", json={"n": 3})
            snap = api.post(f"/v1/sessions/{sid}/snapshots").json()
            api.patch(f"/v1/sessions/{sid}/electrodes/active", json={"power_w": 0})
            api.post(f"/v1/sessions/{sid}/step", json={"n": 2})
            before = api.get(f"/v1/sessions/{sid}").json()
            t_before = temperature(api, sid)
    finally:
        first.stop()  # shutdown checkpoints what changed

    second = LiveServer(make_settings(data), DefaultEngine()).start()
    try:
        with second.client() as api:
            listed = api.get("/v1/sessions").json()["sessions"]
            assert [s["id"] for s in listed] == [sid] and listed[0]["loaded"] is False
            after = api.get(f"/v1/sessions/{sid}").json()
            assert (
                (after["step"], after["time_s"])
                == (before["step"], before["time_s"])
                == (5, pytest.approx(0.15))
            )
            np.testing.assert_array_equal(temperature(api, sid), t_before)
            rep = api.post(f"/v1/sessions/{sid}/step").json()["reports"][0]
            assert rep["step"] == 6 and rep["delivered_power_w"] == 0.0  # the override survived
            assert (
                api.post(f"/v1/sessions/{sid}/snapshots/{snap['id']}/restore").json()["step"] == 3
            )
        with second.client(TOKEN_B) as other:
            assert other.get(f"/v1/sessions/{sid}").status_code == 404  # the owner survived too
    finally:
        second.stop()


def test_autosave_covers_a_crash(tmp_path: Path) -> None:
    data = tmp_path / "data"
    first = LiveServer(make_settings(data, autosave_interval_s=0.2), DefaultEngine()).start()
    try:
        with first.client() as api:
            sid = api.post("/v1/sessions", json=SMALL).json()["id"]
            api.post(f"/v1/sessions/{sid}/step", json={"n": 4})
        rec = first.state.registry.sessions[sid]
        deadline = time.monotonic() + 5
        while rec.dirty and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not rec.dirty
        # a second server reads the data dir while the first never shut down (as after a crash)
        second = LiveServer(make_settings(data), DefaultEngine()).start()
        try:
            with second.client() as api:
                assert api.get(f"/v1/sessions/{sid}").json()["step"] == 4
        finally:
            second.stop()
    finally:
        first.stop()


def test_unreadable_sessions_are_skipped_not_fatal(tmp_path: Path) -> None:
    data = tmp_path / "data"
    (data / "sessions" / "broken").mkdir(parents=True)
    (data / "sessions" / "broken" / "meta.json").write_text("{not json")
    (data / "sessions" / "nocheckpoint").mkdir(parents=True)
    (data / "sessions" / "nocheckpoint" / "meta.json").write_text('{"id": "x", "owner": "y"}')
    live = LiveServer(make_settings(data), DefaultEngine()).start()
    try:
        with live.client() as api:
            assert api.get("/v1/sessions").json()["sessions"] == []
            assert api.get("/readyz").json()["status"] == "ok"
    finally:
        live.stop()


def test_corrupt_checkpoint_is_a_409_not_a_500(tmp_path: Path) -> None:
    data = tmp_path / "data"
    first = LiveServer(make_settings(data), DefaultEngine()).start()
    with first.client() as api:
        sid = api.post("/v1/sessions", json=SMALL).json()["id"]
    first.stop()
    (data / "sessions" / sid / "state.h5").write_bytes(b"garbage")
    second = LiveServer(make_settings(data), DefaultEngine()).start()
    try:
        with second.client() as api:
            r = api.post(f"/v1/sessions/{sid}/step")
            assert r.status_code == 409 and r.json()["error"] == "checkpoint_error"
    finally:
        second.stop()
