"""The SDK reads electrodes back (sync and async) from a real server."""

from __future__ import annotations

import asyncio

import pytest

from diathermy_client import AsyncClient, Client, Electrode, NotFound
from tests.client.conftest import SMALL_GRID, TOKEN_A, LiveServer


def test_sync_electrodes(client: Client) -> None:
    s = client.create_session("default", grid=SMALL_GRID)
    (e,) = client.list_electrodes(s.id)
    assert isinstance(e, Electrode)
    assert e.name == "active" and e.position_m == (0.1, 0.05) and e.power_w == 50.0
    assert e.active and not e.follows_path and e.drive == "power" and e.control_id == 0
    ack = s.move_electrode(0.05, 0.04)
    s.set_power(12.0)
    got = s.electrode()
    assert got.position_m == (0.05, 0.04) and got.power_w == 12.0
    assert got.control_id == ack.control_id + 1
    assert client.get_electrode(s.id, "active") == got
    assert s.electrodes() == [got]
    with pytest.raises(NotFound, match="no electrode 'other'"):
        s.electrode("other")


def test_async_electrodes(live: LiveServer) -> None:
    async def main() -> None:
        async with AsyncClient(live.url, TOKEN_A, timeout_s=30) as client:
            s = await client.create_session("moving-electrode", grid=SMALL_GRID)
            (e0,) = await client.list_electrodes(s.id)
            assert e0.follows_path and e0.position_m == pytest.approx((0.04, 0.05))
            await s.step(5)
            e1 = await s.electrode()
            assert e1.step == 5 and e1.position_m[0] > e0.position_m[0]
            await s.set_electrode(active=False)
            assert (await client.get_electrode(s.id)).active is False
            assert [e.name for e in await s.electrodes()] == ["active"]
            with pytest.raises(NotFound):
                await client.get_electrode(s.id, "other")

    asyncio.run(main())


def test_sdk_sets_and_reads_the_voltage_limit(client: Client) -> None:
    s = client.create_session("default", grid=SMALL_GRID)
    assert s.electrodes()[0].max_voltage_v is None
    s.set_electrode(max_voltage_v=80.0)
    assert s.electrodes()[0].max_voltage_v == 80.0
    s.set_electrode(max_voltage_v=0.0)  # lifts it
    assert s.electrodes()[0].max_voltage_v is None
