"""The WebSocket stream of a session: subscriptions and control messages (``driver.py`` steps).

Every step is published to all subscribers through their one-frame slots. Protocol errors close
the socket with code 4400 and a JSON reason, after an ``error`` message; a rejected value (an
unknown electrode, a position off the block) only answers with an ``error`` message.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from collections import deque
from collections.abc import Mapping
from typing import Any

from pydantic import ValidationError
from starlette.websockets import WebSocket, WebSocketDisconnect, WebSocketState

from diathermy.errors import DiathermyError
from diathermy.scene.io import describe_validation_error
from diathermy.service import engine_ops as ops
from diathermy.service.driver import SessionDriver, driver_of
from diathermy.service.encoding import pack, unpack
from diathermy.service.engine_process import RemoteSim
from diathermy.service.errors import classify
from diathermy.service.exceptions import BadRequestError
from diathermy.service.hub import Frame, FrameSlot, Subscriber, Subscription
from diathermy.service.messages import (
    ElectrodeControl,
    Pause,
    Run,
    Step,
    Subscribe,
    client_message,
)
from diathermy.service.registry import SessionRecord
from diathermy.service.schemas import ElectrodeUpdate
from diathermy.service.sessions import run_locked, update_electrode
from diathermy.service.state import AppState

log = logging.getLogger("diathermy.service.stream")

CLOSE_BAD_MESSAGE = 4400
CLOSE_UNAUTHORIZED = 4401
CLOSE_NOT_FOUND = 4404
CLOSE_TOO_BIG = 1009
CLOSE_POLICY = 1008
CLOSE_SERVER_ERROR = 1011
MAX_PENDING_REPLIES = 64


class ControlFloodError(BadRequestError):
    """The client sends control messages faster than it reads the replies."""


def parse_message(raw: Mapping[str, Any]) -> Any:
    """A client message from a websocket.receive event; raises BadRequestError naming the field."""
    try:
        if raw.get("text") is not None:
            data = json.loads(raw["text"])
        else:
            data = unpack(raw.get("bytes") or b"")
    except ValueError as err:
        raise BadRequestError(f"message is neither JSON text nor msgpack: {err}") from None
    except Exception as err:  # msgpack raises several unrelated types on garbage
        raise BadRequestError(f"message is neither JSON text nor msgpack: {err}") from None
    try:
        return client_message.validate_python(data)
    except ValidationError as err:
        loc = err.errors()[0].get("loc", ()) if err.errors() else ()
        raise BadRequestError(
            describe_validation_error(err), field=".".join(str(p) for p in loc) or None
        ) from None


def close_reason(code: str, message: str, field: str | None) -> str:
    """A JSON close reason that fits the 123-byte limit of a close frame."""
    body = {"error": code, "message": message, "field": field}
    text = json.dumps(body)
    while len(text.encode()) > 123 and body["message"]:
        body["message"] = body["message"][: max(0, len(body["message"]) - 16)]
        text = json.dumps(body)
    return text


class StreamConnection:
    """One client's socket: a receive loop for control messages and a sender task for frames."""

    def __init__(self, ws: WebSocket, rec: SessionRecord, state: AppState) -> None:
        self.ws = ws
        self.rec = rec
        self.state = state
        self.sub = Subscriber(slot=FrameSlot(asyncio.get_running_loop()))
        self.replies: deque[dict[str, Any]] = deque()
        self._sender_task: asyncio.Task[None] | None = None

    async def send(self, msg: dict[str, Any]) -> None:
        """Queue a reply (hello, ack, error) for the sender; never waits on a slow socket."""
        if len(self.replies) >= MAX_PENDING_REPLIES:
            raise ControlFloodError(
                f"over {MAX_PENDING_REPLIES} replies wait to be read: the client sends control "
                "messages faster than it reads"
            )
        self.replies.append(msg)
        self.sub.slot.wake()

    async def _sender(self) -> None:
        """The only writer of the socket: replies first, then the newest frame."""
        while True:
            frame = await self.sub.slot.wait()
            while self.replies:
                await self.ws.send_bytes(pack(self.replies.popleft()))
            if frame is not None:
                await self.ws.send_bytes(frame.to_bytes(self.sub.slot.dropped))
                self.state.metrics.frames_sent.inc()
                if self.sub.first_shown_by(frame):
                    self.sub.awaiting = 0

    async def serve(self) -> None:
        driver = driver_of(self.rec, self.state)
        hello = await run_locked(
            self.rec, self.state.registry, lambda sim: sim.call(ops.hello, self.rec.id)
        )
        await self.send(hello)
        driver.attach(self.sub, self)
        self.state.metrics.stream_clients.inc()
        sender = self._sender_task = asyncio.create_task(self._sender())
        try:
            await self._receive_loop(driver)
            await self._flush(sender)
        finally:
            sender.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await sender
            self.state.metrics.stream_clients.dec()
            await driver.detach(self.sub)

    async def _flush(self, sender: asyncio.Task[None], timeout_s: float = 2.0) -> None:
        """Give the sender a moment to deliver queued replies (e.g. the error before a close)."""
        deadline = time.monotonic() + timeout_s
        while self.replies and not sender.done() and time.monotonic() < deadline:
            await asyncio.sleep(0.005)

    async def _receive_loop(self, driver: SessionDriver) -> None:
        limit = self.state.settings.max_message_bytes
        while True:
            try:
                raw = await self.ws.receive()
            except WebSocketDisconnect:
                return
            if raw["type"] == "websocket.disconnect":
                return
            size = len(raw.get("text") or "") + len(raw.get("bytes") or b"")
            if size > limit:
                await self.close(CLOSE_TOO_BIG, "too_large", f"message over {limit} bytes")
                return
            try:
                msg = parse_message(raw)
            except BadRequestError as err:
                await self.close(CLOSE_BAD_MESSAGE, "bad_message", str(err), err.field)
                return
            try:
                await self._handle(msg, driver)
            except ControlFloodError as err:
                await self.close(CLOSE_POLICY, "too_many_messages", str(err))
                return
            except DiathermyError as err:
                _, code, field = classify(err)
                await self.send(
                    {"type": "error", "error": code, "message": str(err), "field": field}
                )

    async def close(self, code: int, error: str, message: str, field: str | None = None) -> None:
        """Send an ``error`` message, then close with ``code`` and the same error as reason."""
        self.replies.append({"type": "error", "error": error, "message": message, "field": field})
        self.sub.slot.wake()
        if self._sender_task is not None:
            await self._flush(self._sender_task)
            self._sender_task.cancel()
        if self.ws.client_state != WebSocketState.DISCONNECTED:
            with contextlib.suppress(Exception):
                await self.ws.close(code=code, reason=close_reason(error, message, field))

    async def _ack(
        self,
        of: str,
        driver: SessionDriver,
        tag: Any = None,
        step: int | None = None,
        control_id: int | None = None,
    ) -> None:
        if step is None and self.rec.sim is not None:
            step = self.rec.sim.step_index
        await self.send(
            {
                "type": "ack",
                "of": of,
                "step": step,
                "control_id": self.rec.control_id if control_id is None else control_id,
                "tag": tag,
                "running": driver.running,
                "rate_hz": driver.rate_hz,
            }
        )

    async def _handle(self, msg: Any, driver: SessionDriver) -> None:
        if isinstance(msg, Subscribe):
            frame = await self._subscribe(msg)
            await self._ack("subscribe", driver)
            self.sub.slot.put(frame)  # after the ack: the sender sends replies first
        elif isinstance(msg, ElectrodeControl):
            update = ElectrodeUpdate(
                **msg.model_dump(exclude={"type", "name", "tag"}, exclude_none=True)
            )
            control_id, step = await update_electrode(
                registry=self.state.registry, rec=self.rec, name=msg.name, update=update
            )
            self.sub.awaiting = control_id  # its frame goes to this client first (hub.deliver)
            await self._ack("electrode", driver, msg.tag, step, control_id)
        elif isinstance(msg, Run):
            driver.run(msg.rate_hz)
            await self._ack("run", driver)
        elif isinstance(msg, Pause):
            driver.pause()
            await self._ack("pause", driver)
        elif isinstance(msg, Step):
            driver.step(msg.n)
            await self._ack("step", driver)

    async def _subscribe(self, msg: Subscribe) -> Frame:
        """Check and set the subscription; returns the current state as a frame for it."""
        sub = Subscription(
            fields=tuple(dict.fromkeys(msg.fields)),
            every=msg.every,
            dtype=msg.dtype,
            region=msg.region,
        )

        def check_and_encode(sim: RemoteSim) -> Frame:
            frame: Frame = sim.call(ops.subscribe_frame, sub, self.rec.id, self.rec.control_id)
            self.sub.subscription = sub
            return frame

        return await run_locked(self.rec, self.state.registry, check_and_encode)


async def serve_stream(ws: WebSocket, state: AppState, session_id: str) -> None:
    """Authenticate (Authorization header or ?token=), find the session, then serve the stream."""
    await ws.accept()
    header = ws.headers.get("authorization")
    token = ws.query_params.get("token")
    if header is None and token:
        header = f"Bearer {token}"
    try:
        owner = state.tokens.owner(header)
        rec = state.registry.get(owner, session_id)
    except DiathermyError as err:
        status, code, field = classify(err)
        close = CLOSE_UNAUTHORIZED if status == 401 else CLOSE_NOT_FOUND
        error = {"type": "error", "error": code, "message": str(err), "field": field}
        with contextlib.suppress(Exception):
            await ws.send_bytes(pack(error))
        await ws.close(code=close, reason=close_reason(code, str(err), field))
        return
    conn = StreamConnection(ws, rec, state)
    try:
        await conn.serve()
    except WebSocketDisconnect:
        pass
    except DiathermyError as err:  # e.g. a checkpoint that cannot be loaded
        _, code, field = classify(err)
        await conn.close(CLOSE_SERVER_ERROR, code, str(err), field)
