"""``AsyncStream``: frames of one session over a WebSocket, with controls and reconnects."""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections import deque
from typing import Any

from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidURI

from diathermy_client._core import ClientCore
from diathermy_client._errors import DiathermyError, ServerError, StreamClosed, Timeout
from diathermy_client._models import Ack, Frame, Hello
from diathermy_client._stream_core import (
    ReconnectPolicy,
    StreamCore,
    StreamError,
    Subscription,
    electrode_message,
    run_message,
    step_message,
)

_END = object()


class AsyncStream:
    """Frames of one session; send controls while iterating. Use ``async with`` to close cleanly.

    After an unexpected drop it reconnects with backoff, subscribes again, resumes running if it
    was, and skips the frame it already yielded. Closes that a reconnect cannot fix (auth, no such
    session, a refused message) raise the matching error.

    Example::

        async with session.stream(["temperature"], every=2, dtype="float16") as stream:
            ack = await stream.set_electrode(power_w=30.0)
            await stream.run(rate_hz=20)
            async for frame in stream:
                if frame.control_id >= ack.control_id:
                    break
    """

    def __init__(
        self,
        core: ClientCore,
        session_id: str,
        subscription: Subscription,
        *,
        reconnect: ReconnectPolicy | None,
        buffer: int,
        timeout_s: float,
    ) -> None:
        self._sc = StreamCore(core, session_id, subscription)
        self._reconnect = reconnect
        self._timeout_s = timeout_s
        self._buffer = max(1, buffer)
        self._frames: deque[Any] = deque()
        self._arrived = asyncio.Event()
        self._pending: deque[asyncio.Future[Ack]] = deque()
        self._ws: ClientConnection | None = None
        self._reader: asyncio.Task[None] | None = None
        self._closing = False
        self._opened = False
        self._dead = False  # the stream ended for good (a final close, or reconnects gave up)
        self._connected = asyncio.Event()  # clear while reconnecting: controls wait for it
        self.dropped_locally = 0
        """Frames discarded here because the consumer fell ``buffer`` frames behind."""

    # --- lifecycle
    @property
    def hello(self) -> Hello | None:
        """The server's latest ``hello`` (step, fields, effects, electrodes)."""
        return self._sc.hello

    @property
    def reconnects(self) -> int:
        return self._sc.reconnects

    async def __aenter__(self) -> AsyncStream:
        await self.open()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def open(self) -> None:
        """Connect and subscribe (``with`` does this). Example: ``await stream.open()``."""
        if self._opened:
            return
        self._opened = True
        ws = await self._connect()
        acks = await self._start(ws, reconnect=False)
        self._reader = asyncio.create_task(self._read_loop())
        for fut in acks:
            await self._wait(fut)

    async def close(self) -> None:
        """Close the socket (code 1000) and end iteration. Example: ``await stream.close()``."""
        self._closing = True
        if self._ws is not None:
            with contextlib.suppress(Exception):
                await self._ws.close()
        if self._reader is not None:
            self._reader.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._reader
        self._fail_pending(StreamClosed("stream closed by the client"))
        self._push(_END)

    # --- iteration
    def __aiter__(self) -> AsyncStream:
        return self

    async def __anext__(self) -> Frame:
        if not self._opened:
            await self.open()
        while not self._frames:
            self._arrived.clear()
            await self._arrived.wait()
        item = self._frames[0]
        if item is _END:
            raise StopAsyncIteration
        self._frames.popleft()
        if isinstance(item, BaseException):
            self._frames.appendleft(_END)
            raise item
        return item

    async def next_frame(self, timeout_s: float | None = None) -> Frame:
        """The next frame, or ``Timeout`` after ``timeout_s``. Example: ``await s.next_frame(5)``."""
        try:
            return await asyncio.wait_for(self.__anext__(), timeout_s)
        except TimeoutError:
            raise Timeout(f"no frame within {timeout_s} s") from None

    # --- controls
    async def set_electrode(
        self,
        name: str = "active",
        *,
        position_m: tuple[float, float] | None = None,
        power_w: float | None = None,
        current_density_a_per_m2: float | None = None,
        active: bool | None = None,
        max_voltage_v: float | None = None,
        tag: str | int | None = None,
    ) -> Ack:
        """Change an electrode before the next step; frames with ``control_id >= ack.control_id``
        reflect it. Example: ``ack = await stream.set_electrode(position_m=(0.1, 0.05))``."""
        msg = electrode_message(
            name,
            tag,
            position_m=position_m,
            power_w=power_w,
            current_density_a_per_m2=current_density_a_per_m2,
            active=active,
            max_voltage_v=max_voltage_v,
        )
        return await self._control(msg)

    async def run(self, rate_hz: float = 10.0) -> Ack:
        """Step continuously at up to ``rate_hz``. Example: ``await stream.run(30)``."""
        return await self._control(run_message(rate_hz))

    async def pause(self) -> Ack:
        """Stop stepping. Example: ``await stream.pause()``."""
        return await self._control({"type": "pause"})

    async def step(self, n: int = 1) -> Ack:
        """Take n steps now (also while paused). Example: ``await stream.step()``."""
        return await self._control(step_message(n))

    # --- internals
    async def _connect(self) -> ClientConnection:
        try:
            return await connect(
                self._sc.url,
                additional_headers=self._sc.headers,
                open_timeout=self._timeout_s,
                max_size=None,
            )
        except (TimeoutError, OSError, InvalidHandshake, InvalidURI) as err:
            raise StreamClosed(f"cannot connect to {self._sc.url}: {err}") from err

    async def _start(self, ws: ClientConnection, *, reconnect: bool) -> list[asyncio.Future[Ack]]:
        """Read ``hello``, then send the subscription (and ``run`` after a reconnect)."""
        try:
            first = self._sc.decode(await asyncio.wait_for(ws.recv(), self._timeout_s))
            if isinstance(first, StreamError):  # the server explains a close, then closes
                first = self._sc.decode(await asyncio.wait_for(ws.recv(), self._timeout_s))
        except ConnectionClosed as err:
            code, reason = _close_of(err)
            raise self._sc.close_error(code, reason) or self._sc.closed_error(
                code, reason, "closed before hello"
            ) from None
        except TimeoutError:
            raise Timeout(f"no hello from {self._sc.url} within {self._timeout_s} s") from None
        if not isinstance(first, Hello):
            raise ServerError(f"expected hello, got {first!r}")
        self._ws = ws
        self._connected.set()
        futs = []
        for msg in self._sc.on_connected(first, reconnect=reconnect):
            fut: asyncio.Future[Ack] = asyncio.get_running_loop().create_future()
            if reconnect:  # nobody awaits these: their outcome only keeps acks in order
                fut.add_done_callback(lambda f: f.cancelled() or f.exception())
            self._pending.append(fut)
            futs.append(fut)
            await ws.send(json.dumps(msg))
        return futs

    async def _control(self, msg: dict[str, Any]) -> Ack:
        if not self._opened:
            await self.open()
        for attempt in range(2):  # a send that hit a dropped socket was not delivered: resend
            if not self._connected.is_set() and not self._dead:  # reconnecting: wait for it
                with contextlib.suppress(asyncio.TimeoutError):
                    await asyncio.wait_for(self._connected.wait(), self._timeout_s)
            ws = self._ws
            if self._closing or self._dead or ws is None or not self._connected.is_set():
                raise StreamClosed("the stream is closed")
            fut: asyncio.Future[Ack] = asyncio.get_running_loop().create_future()
            self._pending.append(fut)
            try:
                await ws.send(json.dumps(msg))
            except ConnectionClosed as err:
                self._pending.remove(fut)
                if attempt:
                    raise StreamClosed(f"connection lost while sending {msg['type']}") from err
                if self._ws is ws:
                    self._connected.clear()  # the reader reconnects
                continue
            self._sc.sent(msg)
            return await self._wait(fut)
        raise AssertionError("unreachable")

    async def _wait(self, fut: asyncio.Future[Ack]) -> Ack:
        try:
            return await asyncio.wait_for(asyncio.shield(fut), self._timeout_s)
        except TimeoutError:
            raise Timeout(f"no answer from the stream within {self._timeout_s} s") from None

    def _end(self) -> None:
        self._dead = True
        self._connected.set()  # wake controls waiting for a reconnect: they raise StreamClosed

    def _push(self, item: Any) -> None:
        if isinstance(item, Frame):
            frames = sum(isinstance(f, Frame) for f in self._frames)
            if frames >= self._buffer:
                self._frames.popleft()
                self.dropped_locally += 1
        self._frames.append(item)
        self._arrived.set()

    def _resolve(self, msg: Ack | StreamError) -> None:
        fut = self._pending.popleft() if self._pending else None
        if fut is None:
            if isinstance(msg, StreamError):  # a step failed while running: the consumer hears
                self._push(msg.exception())
        elif not fut.done():
            if isinstance(msg, Ack):
                fut.set_result(msg)
            else:
                fut.set_exception(msg.exception())

    def _fail_pending(self, err: DiathermyError) -> None:
        while self._pending:
            fut = self._pending.popleft()
            if not fut.done():
                fut.set_exception(err)
                fut.exception()  # mark retrieved: nobody may be waiting on it any more

    async def _read_loop(self) -> None:
        while True:
            assert self._ws is not None
            try:
                data = await self._ws.recv()
            except ConnectionClosed as err:
                if self._closing:
                    return
                self._connected.clear()
                code, reason = _close_of(err)
                final = self._sc.close_error(code, reason)
                if final is not None or self._reconnect is None:
                    self._fail_pending(final or self._sc.closed_error(code, reason, "dropped"))
                    self._push(final or self._sc.closed_error(code, reason, "dropped"))
                    self._end()
                    return
                self._fail_pending(self._sc.closed_error(code, reason, "reconnecting"))
                if not await self._reconnect_loop(code, reason):
                    self._end()
                    return
                continue
            try:
                msg = self._sc.decode(data)
            except DiathermyError as err:
                self._push(err)
                continue
            if isinstance(msg, Frame):
                if self._sc.accept(msg):
                    self._push(msg)
            elif isinstance(msg, Ack | StreamError):
                self._resolve(msg)

    async def _reconnect_loop(self, code: int | None, reason: str | None) -> bool:
        assert self._reconnect is not None
        last: DiathermyError | None = None
        for delay in self._reconnect.delays():
            await asyncio.sleep(delay)
            if self._closing:
                return False
            try:
                ws = await self._connect()
                await self._start(ws, reconnect=True)
                return True
            except (StreamClosed, ServerError, Timeout) as err:
                last = err
            except DiathermyError as err:  # auth or session gone: no use retrying
                self._push(err)
                return False
        self._push(self._sc.closed_error(code, reason, f"gave up reconnecting ({last})"))
        return False


def _close_of(err: ConnectionClosed) -> tuple[int | None, str | None]:
    frame = err.rcvd
    return (frame.code, frame.reason) if frame is not None else (None, None)
