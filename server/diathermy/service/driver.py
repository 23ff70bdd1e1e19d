"""The stepping driver of a streamed session: continuous at a rate, or n steps on demand.

While running, a worker thread keeps the session lock for as many steps as it can, each one
taken by the session's engine process: it paces itself to the requested rate there and returns
only when paused or when something else waits for the session (an electrode control, a REST read,
a subscription), which then runs before the next step. So the engine's rate does not depend on
the event loop, which only writes frames to sockets. Electrode controls do not stop the batch: they are handed to it and
applied between two steps, so a control waits at most for the step in progress. Steps asked for
with ``step`` are taken one per batch, so that a client reading at once gets every frame.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from typing import Any, Protocol

from diathermy.errors import DiathermyError
from diathermy.service.errors import classify
from diathermy.service.exceptions import LimitExceededError
from diathermy.service.hub import Subscriber
from diathermy.service.registry import SessionRecord
from diathermy.service.sessions import advance, run_locked
from diathermy.service.state import AppState


class StreamClient(Protocol):
    """What the driver needs of a stream connection (``stream.StreamConnection``)."""

    async def send(self, msg: dict[str, Any]) -> None: ...

    async def close(
        self, code: int, error: str, message: str, field: str | None = None
    ) -> None: ...


class SessionDriver:
    """Steps one session for its stream clients (one per session while clients are connected)."""

    def __init__(self, rec: SessionRecord, state: AppState) -> None:
        self.rec = rec
        self.state = state
        self.running = False
        self.rate_hz = 10.0
        self.pending = 0
        self.clients: dict[Subscriber, StreamClient] = {}
        self._wake = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._next_t = 0.0
        self._loop_ref = asyncio.get_running_loop()

    def attach(self, sub: Subscriber, conn: StreamClient) -> None:
        self.clients[sub] = conn
        self.rec.hub.add(sub)
        if self._task is None:
            self._task = asyncio.create_task(self._loop(), name=f"driver-{self.rec.id}")

    async def detach(self, sub: Subscriber) -> None:
        self.clients.pop(sub, None)
        self.rec.hub.remove(sub)
        if not self.clients:
            await self.stop()

    async def stop(self) -> None:
        """Stop stepping and end the task (the last client left, or the session is deleted)."""
        self.running = False
        self.pending = 0
        self.rec.interrupt.set()
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        if self.rec.driver is self:
            self.rec.driver = None

    def run(self, rate_hz: float) -> None:
        self.rate_hz = min(rate_hz, self.state.settings.max_stream_rate_hz)
        if not self.running:
            self._next_t = time.monotonic()
        self.running = True
        self._notify()

    def pause(self) -> None:
        self.running = False
        self._notify()

    def step(self, n: int) -> None:
        """Queue ``n`` more steps; the steps queued at once are bounded like a REST request."""
        limit = self.state.settings.max_steps_per_request
        if self.pending + n > limit:
            raise LimitExceededError(
                f"{n} more steps would queue {self.pending + n}, over the limit of {limit} "
                "steps per request",
                field="n",
            )
        self.pending += n
        self._notify()

    def _notify(self) -> None:
        self._wake.set()
        self.rec.interrupt.set()

    async def _broadcast(self, msg: dict[str, Any]) -> None:
        for conn in list(self.clients.values()):
            with contextlib.suppress(Exception):
                await conn.send(msg)

    async def close_all(self, code: int, error: str, message: str, field: str | None) -> None:
        """Stop stepping, send every client an ``error`` and close its socket (session deleted)."""
        await self.stop()
        for conn in list(self.clients.values()):
            await conn.close(code, error, message, field)

    def _batch(self, sim: Any) -> bool:
        """Step while there is work and nobody else waits for the session (worker thread).

        Electrode controls offered meanwhile (``SessionRecord.offer``) are applied between
        steps. Returns True after taking one requested step (the event loop counts it off)."""
        rec = self.rec
        with rec.batch_lock:
            rec.batch_active = True
        try:
            return self._steps(sim)
        finally:
            while True:  # apply what was offered before the batch ends, then stop taking more
                self._apply_controls(sim)
                with rec.batch_lock:
                    if not rec.controls:
                        rec.batch_active = False
                        break

    def _steps(self, sim: Any) -> bool:
        rec, interrupt = self.rec, self.rec.interrupt
        while rec.waiting == 0 and not rec.deleted:
            interrupt.clear()
            self._apply_controls(sim)
            if self.pending:  # requested steps: one per batch, so that each frame goes out
                advance(rec, self.state.registry, sim, 1, self.state.metrics)
                return True
            if self.running:
                delay = self._next_t - time.monotonic()
                if delay > 0:
                    interrupt.wait(delay)  # woken early by a control, a pause or a stop
                    continue
                self._next_t = max(self._next_t + 1.0 / self.rate_hz, time.monotonic())
            else:
                return False
            advance(rec, self.state.registry, sim, 1, self.state.metrics)
        return False

    def _apply_controls(self, sim: Any) -> None:
        """Run the offered controls in order and hand each its result (worker thread)."""
        loop = self._loop_ref
        while True:
            with self.rec.batch_lock:
                if not self.rec.controls:
                    return
                fn, fut = self.rec.controls.popleft()
            try:
                result = fn(sim)
            except Exception as err:
                loop.call_soon_threadsafe(_settle, fut, None, err)
            else:
                loop.call_soon_threadsafe(_settle, fut, result, None)

    async def _loop(self) -> None:
        while True:
            if not self.running and self.pending == 0:
                self._wake.clear()
                await self._wake.wait()
                continue
            try:
                if await run_locked(self.rec, self.state.registry, self._batch):
                    self.pending = max(0, self.pending - 1)
            except DiathermyError as err:
                self.running, self.pending = False, 0
                _, code, field = classify(err)
                await self._broadcast(
                    {"type": "error", "error": code, "message": str(err), "field": field}
                )
            await asyncio.sleep(0)  # whoever interrupted the batch has the lock next (FIFO)


def _settle(fut: asyncio.Future[Any], result: Any, err: BaseException | None) -> None:
    if fut.done():  # the waiter was cancelled (its client left)
        return
    if err is not None:
        fut.set_exception(err)
    else:
        fut.set_result(result)


def driver_of(rec: SessionRecord, state: AppState) -> SessionDriver:
    if rec.driver is None:
        rec.driver = SessionDriver(rec, state)
    return rec.driver
