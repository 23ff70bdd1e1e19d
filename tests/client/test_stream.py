"""Streaming with the SDK: frames as numpy arrays, controls while streaming, reconnects."""

from __future__ import annotations

import asyncio
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from diathermy.service.engine import DefaultEngine
from diathermy_client import (
    AsyncClient,
    AuthError,
    Client,
    Frame,
    NotFound,
    ReconnectPolicy,
    StreamClosed,
)
from tests.client.conftest import SMALL_GRID, TOKEN_A, TOKEN_B, LiveServer, make_settings
from tests.service.conftest import free_port


def test_sync_stream_with_controls(client: Client) -> None:
    s = client.create_session("default", grid=SMALL_GRID)
    with s.stream(["temperature", "displacement"], dtype="float16", timeout_s=10) as st:
        assert st.hello is not None and st.hello.electrodes == ["active"]
        first = st.next_frame(5)  # the current state comes at once
        assert isinstance(first, Frame) and first.step == 0
        assert first["temperature"].shape == SMALL_GRID and first["temperature"].dtype == np.float16
        assert first["displacement"].shape == (*SMALL_GRID, 3)
        ack = st.run(100)
        assert ack.running and ack.of == "run"
        steps = [st.next_frame(5).step for _ in range(4)]
        assert steps == sorted(steps) and steps[-1] >= 4
        ack = st.set_electrode(power_w=0.0, tag="off")
        assert ack.tag == "off" and ack.control_id == 1
        off = next(f for f in st if f.control_id >= ack.control_id)
        assert off.report is not None and off.report.delivered_power_w == 0.0
        st.pause()
        with pytest.raises(TimeoutError):  # drain what was in flight, then silence
            while True:
                st.next_frame(0.5)
        before = s.refresh().step
        st.step(2)
        a, b = st.next_frame(5), st.next_frame(5)
        assert (a.step, b.step) == (before + 1, before + 2)
    with pytest.raises(StreamClosed):
        st.next_frame(1)
    assert st.dropped_locally == 0


def test_sync_stream_of_the_top_face(client: Client) -> None:
    """region='top': the top node layer, (ny, nx[, 3]), equal to the volume frame's last layer."""
    s = client.create_session("default", grid=SMALL_GRID)
    s.step(3)
    fields = ["temperature", "displacement"]
    with s.stream(fields, region="top", timeout_s=10) as top_stream:
        top = top_stream.next_frame(5)
    with s.stream(fields, timeout_s=10) as volume_stream:
        vol = volume_stream.next_frame(5)
    assert top.step == vol.step == 3
    assert top["temperature"].shape == SMALL_GRID[1:]
    assert top["displacement"].shape == (*SMALL_GRID[1:], 3)
    for name in fields:
        assert np.array_equal(top[name], vol[name][-1]), name
    assert top["temperature"].max() > 310.15  # the electrode heats the top face


def test_async_stream_every_kth_and_controls(live: LiveServer) -> None:
    async def main() -> None:
        async with AsyncClient(live.url, TOKEN_A) as client:
            s = await client.create_session("default", grid=SMALL_GRID)
            async with s.stream(["temperature"], every=2) as st:
                assert (await st.next_frame(5)).step == 0
                await st.step(6)
                got = [(await st.next_frame(5)).step for _ in range(3)]
                assert got == [2, 4, 6]
                ack = await st.set_electrode(position_m=(0.05, 0.05), power_w=30.0)
                await st.run(50)
                async for frame in st:
                    if frame.control_id >= ack.control_id:
                        assert frame.report is not None
                        assert frame.report.delivered_power_w == pytest.approx(30.0)
                        break
                await st.pause()
            # `async for` straight over a stream opens it on first use
            stream = s.stream(["level_set"])
            async for frame in stream:
                assert frame["level_set"].shape == SMALL_GRID
                break
            await stream.close()

    asyncio.run(main())


def restart(live: LiveServer, data: Path) -> LiveServer:
    live.stop()
    time.sleep(0.5)  # the client sees the drop and starts backing off
    return LiveServer(make_settings(data, port=live.settings.port), DefaultEngine()).start()


def test_sync_stream_resumes_after_a_server_restart(tmp_path: Path) -> None:
    data = tmp_path / "data"
    live = LiveServer(make_settings(data, port=free_port()), DefaultEngine()).start()
    try:
        with Client(live.url, TOKEN_A) as client:
            s = client.create_session("default", grid=SMALL_GRID)
            policy = ReconnectPolicy(attempts=20, backoff_s=0.05, max_backoff_s=0.5)
            with s.stream(["temperature"], reconnect=policy, timeout_s=10) as st:
                st.run(50)
                seen = [st.next_frame(5).step for _ in range(5)]
                live = restart(live, data)  # shutdown checkpoints the session
                # frames already queued before the drop may come first: drain them
                for _ in range(200):
                    if st.reconnects:
                        break
                    st.next_frame(20)
                after = [st.next_frame(20).step for _ in range(5)]
                assert st.reconnects == 1
                # resumed from the latest step (checkpointed at shutdown), running again
                assert after[0] >= seen[-1] and after == sorted(after) and after[-1] > after[0]
                assert st.hello is not None and st.hello.step >= seen[-1]
                ack = st.pause()  # controls work on the new socket
                assert not ack.running
    finally:
        live.stop()


def test_async_stream_resumes_after_a_server_restart(tmp_path: Path) -> None:
    data = tmp_path / "data"
    holder = {"live": LiveServer(make_settings(data, port=free_port()), DefaultEngine()).start()}

    async def main() -> None:
        live = holder["live"]
        async with AsyncClient(live.url, TOKEN_A) as client:
            s = await client.create_session("default", grid=SMALL_GRID)
            policy = ReconnectPolicy(attempts=20, backoff_s=0.05, max_backoff_s=0.5)
            async with s.stream(["temperature"], reconnect=policy, timeout_s=10) as st:
                await st.step(3)
                seen = [(await st.next_frame(5)).step for _ in range(4)]
                assert seen == [0, 1, 2, 3]
                await asyncio.to_thread(lambda: holder.update(live=restart(live, data)))
                await st.step(2)  # paused before: the stream resumes paused, controls work
                after = [(await st.next_frame(20)).step for _ in range(2)]
                assert after == [4, 5] and st.reconnects == 1

    try:
        asyncio.run(main())
    finally:
        holder["live"].stop()


def test_stream_errors(live: LiveServer, client: Client) -> None:
    s = client.create_session("default", grid=SMALL_GRID)
    with pytest.raises(NotFound):
        client.stream("nope", ["temperature"]).open()
    with Client(live.url, "wrong") as bad, pytest.raises(AuthError):
        bad.stream(s.id, ["temperature"]).open()
    with Client(live.url, TOKEN_B) as other, pytest.raises(NotFound):
        other.stream(s.id, ["temperature"]).open()
    with pytest.raises(Exception) as info:  # an unknown field: refused, stream stays usable
        client.stream(s.id, ["nope"]).open()
    assert getattr(info.value, "field", None) == "fields.0"
    with s.stream(["temperature"]) as st:
        with pytest.raises(Exception) as info:
            st.set_electrode("ghost", power_w=1.0)
        assert getattr(info.value, "field", None) == "name"
        assert st.step().of == "step"

    # without reconnects a dropped server ends the stream with StreamClosed
    st = s.stream(["temperature"], reconnect=None)
    st.open()
    st.next_frame(5)
    threading.Thread(target=live.stop).start()
    with pytest.raises(StreamClosed):
        while True:
            st.next_frame(10)
    st.close()
