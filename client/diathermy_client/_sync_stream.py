"""``Stream``: the blocking twin of ``AsyncStream`` (a reader thread feeds the iterator)."""

from __future__ import annotations

import contextlib
import json
import threading
import time
from collections import deque
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout
from typing import Any

from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidURI
from websockets.sync.client import ClientConnection, connect

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


class Stream:
    """Frames of one session; send controls while iterating. Use ``with`` to close cleanly.

    After an unexpected drop it reconnects with backoff, subscribes again, resumes running if it
    was, and skips the frame it already yielded. Closes that a reconnect cannot fix (auth, no such
    session, a refused message) raise the matching error.

    Example::

        with session.stream(["temperature", "level_set"], every=5) as stream:
            stream.run(rate_hz=20)
            for frame in stream:
                print(frame.step, frame["temperature"].max())
                if frame.step >= 50:
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
        self._cond = threading.Condition()
        self._pending: deque[Future[Ack]] = deque()
        self._send_lock = threading.Lock()
        self._ws: ClientConnection | None = None
        self._reader: threading.Thread | None = None
        self._closing = False
        self._opened = False
        self._dead = False  # the stream ended for good (a final close, or reconnects gave up)
        self._connected = threading.Event()  # clear while reconnecting: controls wait for it
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

    def __enter__(self) -> Stream:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def open(self) -> None:
        """Connect and subscribe (``with`` does this). Example: ``stream.open()``."""
        if self._opened:
            return
        self._opened = True
        ws = self._connect()
        acks = self._start(ws, reconnect=False)
        self._reader = threading.Thread(
            target=self._read_loop, name="diathermy-stream", daemon=True
        )
        self._reader.start()
        for fut in acks:
            self._wait(fut)

    def close(self) -> None:
        """Close the socket (code 1000) and end iteration. Example: ``stream.close()``."""
        self._closing = True
        if self._ws is not None:
            with contextlib.suppress(Exception):
                self._ws.close()
        if self._reader is not None and self._reader is not threading.current_thread():
            self._reader.join(timeout=self._timeout_s)
        self._fail_pending(StreamClosed("stream closed by the client"))
        self._push(_END)

    # --- iteration
    def __iter__(self) -> Stream:
        return self

    def __next__(self) -> Frame:
        return self._next(None)

    def next_frame(self, timeout_s: float | None = None) -> Frame:
        """The next frame, or ``Timeout`` after ``timeout_s``. Example: ``stream.next_frame(5)``."""
        try:
            return self._next(timeout_s)
        except StopIteration:
            raise StreamClosed("the stream is closed") from None

    def _next(self, timeout_s: float | None) -> Frame:
        if not self._opened:
            self.open()
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        with self._cond:
            while not self._frames:
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    raise Timeout(f"no frame within {timeout_s} s")
                self._cond.wait(left)
            item = self._frames[0]
            if item is _END:
                raise StopIteration
            self._frames.popleft()
            if isinstance(item, BaseException):
                self._frames.appendleft(_END)
                raise item
            return item

    # --- controls
    def set_electrode(
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
        reflect it. Example: ``ack = stream.set_electrode(position_m=(0.1, 0.05))``."""
        msg = electrode_message(
            name,
            tag,
            position_m=position_m,
            power_w=power_w,
            current_density_a_per_m2=current_density_a_per_m2,
            active=active,
            max_voltage_v=max_voltage_v,
        )
        return self._control(msg)

    def run(self, rate_hz: float = 10.0) -> Ack:
        """Step continuously at up to ``rate_hz``. Example: ``stream.run(30)``."""
        return self._control(run_message(rate_hz))

    def pause(self) -> Ack:
        """Stop stepping. Example: ``stream.pause()``."""
        return self._control({"type": "pause"})

    def step(self, n: int = 1) -> Ack:
        """Take n steps now (also while paused). Example: ``stream.step()``."""
        return self._control(step_message(n))

    # --- internals
    def _connect(self) -> ClientConnection:
        try:
            ws = connect(
                self._sc.url,
                additional_headers=self._sc.headers,
                open_timeout=self._timeout_s,
                max_size=None,
            )
            # entering marks it as managed (websockets >= 17.1 warns otherwise); close() ends it
            return ws.__enter__()
        except (OSError, InvalidHandshake, InvalidURI, TimeoutError) as err:
            raise StreamClosed(f"cannot connect to {self._sc.url}: {err}") from err

    def _start(self, ws: ClientConnection, *, reconnect: bool) -> list[Future[Ack]]:
        """Read ``hello``, then send the subscription (and ``run`` after a reconnect)."""
        try:
            first = self._sc.decode(ws.recv(timeout=self._timeout_s))
            if isinstance(first, StreamError):  # the server explains a close, then closes
                first = self._sc.decode(ws.recv(timeout=self._timeout_s))
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
            fut: Future[Ack] = Future()
            with self._send_lock:
                self._pending.append(fut)
                ws.send(json.dumps(msg))
            futs.append(fut)
        return futs

    def _control(self, msg: dict[str, Any]) -> Ack:
        if not self._opened:
            self.open()
        for attempt in range(2):  # a send that hit a dropped socket was not delivered: resend
            if not self._connected.is_set() and not self._dead:  # reconnecting: wait for it
                self._connected.wait(self._timeout_s)
            ws = self._ws
            if self._closing or self._dead or ws is None or not self._connected.is_set():
                raise StreamClosed("the stream is closed")
            fut: Future[Ack] = Future()
            try:
                with self._send_lock:  # pending order must match send order
                    self._pending.append(fut)
                    ws.send(json.dumps(msg))
            except ConnectionClosed as err:
                with self._send_lock:
                    if fut in self._pending:
                        self._pending.remove(fut)
                if attempt:
                    raise StreamClosed(f"connection lost while sending {msg['type']}") from err
                if self._ws is ws:
                    self._connected.clear()  # the reader reconnects
                continue
            self._sc.sent(msg)
            return self._wait(fut)
        raise AssertionError("unreachable")

    def _wait(self, fut: Future[Ack]) -> Ack:
        try:
            return fut.result(timeout=self._timeout_s)
        except FutureTimeout:
            raise Timeout(f"no answer from the stream within {self._timeout_s} s") from None

    def _end(self) -> None:
        self._dead = True
        self._connected.set()  # wake controls waiting for a reconnect: they raise StreamClosed

    def _push(self, item: Any) -> None:
        with self._cond:
            if isinstance(item, Frame):
                frames = sum(isinstance(f, Frame) for f in self._frames)
                if frames >= self._buffer:
                    self._frames.popleft()
                    self.dropped_locally += 1
            self._frames.append(item)
            self._cond.notify_all()

    def _resolve(self, msg: Ack | StreamError) -> None:
        with self._send_lock:
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
        with self._send_lock:
            pending, self._pending = list(self._pending), deque()
        for fut in pending:
            if not fut.done():
                fut.set_exception(err)

    def _read_loop(self) -> None:
        while True:
            ws = self._ws
            assert ws is not None
            try:
                data = ws.recv()
            except ConnectionClosed as err:
                if self._closing:
                    return
                self._connected.clear()
                code, reason = _close_of(err)
                final = self._sc.close_error(code, reason)
                if final is not None or self._reconnect is None:
                    end = final or self._sc.closed_error(code, reason, "dropped")
                    self._fail_pending(end)
                    self._push(end)
                    self._end()
                    return
                self._fail_pending(self._sc.closed_error(code, reason, "reconnecting"))
                if not self._reconnect_loop(code, reason):
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

    def _reconnect_loop(self, code: int | None, reason: str | None) -> bool:
        assert self._reconnect is not None
        last: DiathermyError | None = None
        for delay in self._reconnect.delays():
            time.sleep(delay)
            if self._closing:
                return False
            try:
                ws = self._connect()
                self._start(ws, reconnect=True)
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
