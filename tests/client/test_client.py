"""Every public method of Client/Session and AsyncClient/AsyncSession against a live server."""

from __future__ import annotations

import asyncio
from pathlib import Path

import numpy as np
import pytest

from diathermy_client import (
    AsyncClient,
    Client,
    ElectrodeAck,
    Fields,
    Scene,
    SessionInfo,
    Snapshot,
    StepResult,
    Surface,
)
from tests.client.conftest import QUICK_CUT_SCENE, SMALL_GRID, TOKEN_A, LiveServer


def test_sync_client_every_method(live: LiveServer, client: Client, tmp_path: Path) -> None:
    assert client.health().status == "ok" and client.ready().status == "ok"
    scenes = client.list_scenes()
    assert {"default", "moving-electrode", "coagulation"} <= set(scenes)
    assert isinstance(scenes["default"], Scene) and scenes["default"].grid == (33, 33, 65)
    assert (scenes["default"].model_extra or {})["resolution"]["fine_m"] == 1e-3  # graded

    s = client.create_session("default", grid=SMALL_GRID)
    assert isinstance(s.info, SessionInfo) and s.info.grid.shape == SMALL_GRID
    assert s.info.dof_counts["temperature"] == 225 and s.info.step == 0
    assert [x.id for x in client.sessions()] == [s.id]
    assert [x.id for x in client.list_sessions()] == [s.id]
    assert client.session(s.id).info.id == s.id == client.get_session(s.id).id

    res = s.step(2)
    assert isinstance(res, StepResult) and res.step == 2 and len(res.reports) == 2
    assert res.reports[0].delivered_power_w == pytest.approx(50.0)
    assert res.reports[0].effects["electric"].ran
    assert client.step(s.id).step == 3
    assert s.refresh().step == 3 and s.info.last_report is not None

    ack = s.set_power(20.0)
    assert isinstance(ack, ElectrodeAck) and ack.control_id == 1 and ack.name == "active"
    assert s.step().reports[0].delivered_power_w == pytest.approx(20.0)
    assert s.move_electrode(0.05, 0.04).control_id == 2
    assert s.set_electrode(active=False).control_id == 3
    assert s.step().reports[0].delivered_power_w == 0.0
    ack = client.update_electrode(s.id, active=True, current_density_a_per_m2=1e4)
    assert ack.control_id == 4

    f = s.fields(["temperature", "displacement", "joule_heat"])
    assert isinstance(f, Fields) and f.step == 5 and f.grid is not None
    assert f["temperature"].shape == SMALL_GRID and f["temperature"].dtype == np.float32
    assert f["displacement"].shape == (*SMALL_GRID, 3) and f["joule_heat"].ndim == 1
    assert f.grid.shape == SMALL_GRID and f.grid.size_m == pytest.approx((0.2, 0.1, 0.1))
    t64 = s.field("temperature", dtype="float64")
    assert t64.dtype == np.float64 and t64.max() > 310.15  # heated
    np.testing.assert_allclose(t64, f["temperature"], rtol=1e-6)
    npz = client.read_fields(s.id, "temperature", dtype="float64", format="npz")
    np.testing.assert_array_equal(npz["temperature"], t64)
    assert npz.step == 5 and npz.grid is None

    surf = s.surface()
    assert isinstance(surf, Surface) and surf.is_empty and surf.vertices_m.shape == (0, 3)
    assert client.read_surface(s.id).step == 5

    data = s.vtu(tmp_path / "state.vtu")
    assert b"<VTKFile" in data and (tmp_path / "state.vtu").read_bytes() == data
    assert client.read_vtu(s.id) == data

    snap = s.snapshot()
    assert isinstance(snap, Snapshot) and snap.step == 5
    s.step(2)
    assert [x.id for x in s.snapshots()] == [snap.id] == [x.id for x in client.list_snapshots(s.id)]
    assert s.restore(snap).step == 5 and s.info.step == 5
    np.testing.assert_array_equal(s.field("temperature", dtype="float64"), t64)
    assert client.restore_snapshot(s.id, snap.id).step == 5
    assert client.take_snapshot(s.id).step == 5

    s.delete()
    assert client.list_sessions() == []
    with client.create_session(scene=scenes["coagulation"], grid=SMALL_GRID) as s2:
        assert s2.info.effects == ["electric", "thermal", "thermal_damage"]
    assert client.list_sessions() == []  # leaving `with` deleted it
    other = client.create_session(grid=SMALL_GRID)
    assert other.info.scene_name == "default"
    client.delete_session(other.id)
    assert client.list_sessions() == []


def test_inline_scene_and_cut_surface(client: Client) -> None:
    s = client.create_session(scene=QUICK_CUT_SCENE)
    for _ in range(30):
        if s.step().reports[0].cut_volume_m3:
            break
    surf = s.surface()
    assert not surf.is_empty and surf.faces.max() < len(surf.vertices_m)
    phi = s.field("level_set", dtype="float64")
    assert phi.min() < 0 < phi.max()  # removed and healthy tissue


def test_async_client_every_method(live: LiveServer, tmp_path: Path) -> None:
    async def main() -> None:
        async with AsyncClient(live.url, TOKEN_A) as client:
            assert (await client.health()).status == "ok"
            assert (await client.ready()).status == "ok"
            assert "default" in await client.list_scenes()
            s = await client.create_session("default", grid=SMALL_GRID)
            assert [x.id for x in await client.sessions()] == [s.id]
            assert [x.id for x in await client.list_sessions()] == [s.id]
            assert (await client.session(s.id)).id == (await client.get_session(s.id)).id
            assert (await s.step(2)).step == 2 and (await client.step(s.id)).step == 3
            assert (await s.refresh()).step == 3
            assert (await s.set_power(0.0)).control_id == 1
            assert (await s.step()).reports[0].delivered_power_w == 0.0
            assert (await s.move_electrode(0.1, 0.06)).control_id == 2
            assert (await s.set_electrode(power_w=10.0)).control_id == 3
            assert (await client.update_electrode(s.id, power_w=12.0)).control_id == 4
            assert (await s.step()).reports[0].delivered_power_w == pytest.approx(12.0)
            f = await s.fields(["temperature", "level_set"])
            assert f["level_set"].shape == SMALL_GRID and f.step == 5
            assert (await s.field("temperature")).max() > 310.15
            t = await client.read_fields(s.id, ["temperature"], format="npz", dtype="float64")
            assert t["temperature"].dtype == np.float64
            assert (await s.surface()).is_empty and (await client.read_surface(s.id)).step == 5
            assert b"<VTKFile" in await s.vtu(tmp_path / "a.vtu")
            assert b"<VTKFile" in await client.read_vtu(s.id)
            snap = await s.snapshot()
            await s.step(2)
            assert [x.id for x in await s.snapshots()] == [snap.id]
            assert [x.id for x in await client.list_snapshots(s.id)] == [snap.id]
            assert (await s.restore(snap)).step == 5
            assert (await client.restore_snapshot(s.id, snap)).step == 5
            assert (await client.take_snapshot(s.id)).step == 5
            async with await client.create_session("coagulation", grid=SMALL_GRID) as s2:
                assert "thermal_damage" in s2.info.effects
            await s.delete()
            assert await client.list_sessions() == []
            other = await client.create_session("default", grid=SMALL_GRID)
            await client.delete_session(other.id)
        assert client._http.is_closed

    asyncio.run(main())
