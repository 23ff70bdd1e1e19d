"""The stepping driver of a streamed session: continuous at a rate, or n steps on demand.

While running, a worker thread keeps the session lock for as many steps as it can, each one
taken by the session's engine process: it paces itself to the requested rate there and returns
only when paused or when something else waits for the session (a REST read, a subscription, an
autosave), which then runs after the steps in flight. The batch keeps up to ``STEPS_IN_FLIGHT``
step requests in flight (``engine_process.py``), so the engine starts the next step while the
worker thread journals the last one and hands its frames to the event loop, which only writes
bytes to sockets. Electrode controls do not stop the batch: they go to the engine at once, which
applies them before its next step (ahead of a queued step), so a control waits at most for the
step in progress; the batch journals steps and controls in the order the engine took them.
Steps asked for with ``step`` are taken one per batch, so that a client reading at once gets
every frame.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from typing import Any, Protocol

from diathermy.errors import DiathermyError
from diathermy.service import engine_ops as ops
from diathermy.service.engine_process import RemoteSim
from diathermy.service.errors import classify
from diathermy.service.exceptions import EngineProcessError, LimitExceededError
from diathermy.service.hub import Subscriber
from diathermy.service.registry import SessionRecord
from diathermy.service.sessions import control_applied, publish_step, run_locked
from diathermy.service.state import AppState

STEPS_IN_FLIGHT = 2
"""Step requests a stream keeps in flight: the one the engine takes, and the next one."""


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
        self._steps_sent = 0  # step requests in flight (worker thread)
        self._error: Exception | None = None  # a step that failed in the batch

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

    def _batch(self, sim: RemoteSim) -> bool:
        """Step while there is work and nobody else waits for the session (worker thread).

        Electrode controls offered meanwhile (``SessionRecord.offer``) are journalled as their
        replies come. Returns True after taking one requested step (the event loop counts it
        off). Everything in flight is received before it returns."""
        rec = self.rec
        self._error = None
        with rec.batch_lock:
            rec.batch_active = True
        try:
            took = self._steps(sim)
        finally:
            with rec.batch_lock:  # no more controls; take the replies of those sent
                rec.batch_active = False
            while sim.in_flight:
                self._receive(sim)
        if self._error is not None:
            raise self._error
        return took

    def _steps(self, sim: RemoteSim) -> bool:
        rec, interrupt = self.rec, self.rec.interrupt
        while rec.waiting == 0 and not rec.deleted and self._error is None:
            interrupt.clear()
            if self.pending:  # requested steps: one per batch, so that each frame goes out
                while self._steps_sent:
                    self._receive(sim)
                if self._error is not None:
                    break
                self._send_step(sim)
                while self._steps_sent:
                    self._receive(sim)
                return self._error is None
            delay: float | None = None
            if self.running and self._steps_sent < STEPS_IN_FLIGHT:
                delay = self._next_t - time.monotonic()
                if delay <= 0:
                    self._next_t = max(self._next_t + 1.0 / self.rate_hz, time.monotonic())
                    self._send_step(sim)
                    continue
            elif not self.running and not sim.in_flight:
                return False
            if not sim.in_flight:
                interrupt.wait(delay)  # woken early by a control, a pause or a stop
            elif sim.poll(delay):  # a reply, or the next step is due
                self._receive(sim)
        return False

    def _send_step(self, sim: RemoteSim) -> None:
        subs = self.rec.hub.subscriptions()
        sim.submit(ops.step_frames, subs, self.rec.id, self.rec.control_id)
        self._steps_sent += 1

    def _receive(self, sim: RemoteSim) -> None:
        """Take the engine's next reply: journal then publish a step, or journal then settle a
        control (worker thread). A failed step is kept in ``_error`` and stops the batch."""
        rec = self.rec
        try:
            reply = sim.receive()
        except EngineProcessError as err:
            self._steps_sent = 0
            self._fail_controls(err)
            raise
        with rec.batch_lock:
            offered = rec.controls.pop(reply.id, None)
        if offered is not None:
            control, fut = offered
            if reply.ok:
                result = control_applied(rec, self.state.registry, control, reply.value)
                self._loop_ref.call_soon_threadsafe(_settle, fut, result, None)
            else:
                self._loop_ref.call_soon_threadsafe(_settle, fut, None, reply.value)
            return
        self._steps_sent -= 1
        if not reply.ok:
            self._error = self._error or reply.value
            return
        report, frames = reply.value
        publish_step(rec, self.state.registry, self.state.metrics, report, frames)

    def _fail_controls(self, err: Exception) -> None:
        with self.rec.batch_lock:
            offered, self.rec.controls = self.rec.controls, {}
        for _, fut in offered.values():
            self._loop_ref.call_soon_threadsafe(_settle, fut, None, err)

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
