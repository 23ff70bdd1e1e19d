"""The stream protocol without I/O: messages to send, decoding what arrives, which frames to
yield after a reconnect, which closes end the stream, and the reconnect backoff."""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from diathermy_client._core import ClientCore, decode_array, unpack
from diathermy_client._errors import (
    AuthError,
    Conflict,
    DiathermyError,
    InvalidRequest,
    LimitExceeded,
    NotFound,
    ServerError,
    StreamClosed,
)
from diathermy_client._models import (
    Ack,
    ElectrodeUpdate,
    Frame,
    Hello,
    Region,
    StepReport,
    Surface,
    WireDtype,
)

FINAL_CLOSES: dict[int, type[DiathermyError]] = {
    4401: AuthError,
    4404: NotFound,
    4400: InvalidRequest,
    1009: LimitExceeded,
}
"""Closes that a reconnect cannot fix, and the error each stands for."""
_CODE_ERRORS: dict[str, type[DiathermyError]] = {
    "busy": Conflict,
    "checkpoint_error": Conflict,
    "not_found": NotFound,
    "unauthorized": AuthError,
    "limit_exceeded": LimitExceeded,
    "too_large": LimitExceeded,
    "internal": ServerError,
}


@dataclass(frozen=True)
class Subscription:
    """What frames carry: field names, every k-th step, float16/float32, volume, its top layer or the cut surface."""

    fields: tuple[str, ...] = ()
    every: int = 1
    dtype: WireDtype = "float32"
    region: Region = "volume"

    def message(self) -> dict[str, Any]:
        return {
            "type": "subscribe",
            "fields": list(self.fields),
            "every": self.every,
            "dtype": self.dtype,
            "region": self.region,
        }


@dataclass(frozen=True)
class StreamError:
    """An ``error`` message: a rejected control, or a step that failed while running."""

    error: str
    message: str
    field: str | None = None

    def exception(self) -> DiathermyError:
        cls = _CODE_ERRORS.get(self.error, InvalidRequest)
        return cls(self.message, code=self.error, field=self.field)


@dataclass(frozen=True)
class ReconnectPolicy:
    """Reconnect after an unexpected drop: up to ``attempts`` tries, delays doubling to a cap."""

    attempts: int = 8
    backoff_s: float = 0.1
    max_backoff_s: float = 2.0

    def delays(self) -> Iterator[float]:
        for k in range(self.attempts):
            yield min(self.max_backoff_s, self.backoff_s * 2**k)


DEFAULT_RECONNECT = ReconnectPolicy()


def electrode_message(name: str, tag: str | int | None = None, **changes: Any) -> dict[str, Any]:
    body = ElectrodeUpdate(**changes).model_dump(exclude_none=True)
    return {"type": "electrode", "name": name, **body, "tag": tag}


def run_message(rate_hz: float) -> dict[str, Any]:
    if not 0 < rate_hz < float("inf"):  # the server would close the stream (4400)
        raise InvalidRequest(f"rate_hz must be a finite number > 0, got {rate_hz}", field="rate_hz")
    return {"type": "run", "rate_hz": float(rate_hz)}


def step_message(n: int) -> dict[str, Any]:
    if not 1 <= n <= 1000:
        raise InvalidRequest(f"n must be in 1..1000, got {n}", field="n")
    return {"type": "step", "n": int(n)}


def decode_frame(msg: dict[str, Any]) -> Frame:
    surface = None
    if msg.get("surface"):
        s = msg["surface"]
        surface = Surface(
            step=int(msg["step"]),
            time_s=float(msg["time_s"]),
            vertices_m=decode_array(s["vertices"]).reshape(-1, 3),
            faces=decode_array(s["faces"]).reshape(-1, 3),
        )
    report = msg.get("report")
    return Frame(
        session=str(msg["session"]),
        step=int(msg["step"]),
        time_s=float(msg["time_s"]),
        control_id=int(msg["control_id"]),
        dropped=int(msg.get("dropped", 0)),
        report=StepReport.model_validate(report) if report else None,
        fields={n: decode_array(a) for n, a in (msg.get("fields") or {}).items()},
        surface=surface,
    )


class StreamCore:
    """The state a stream keeps across reconnects: subscription, run state, the last step seen."""

    def __init__(self, core: ClientCore, session_id: str, subscription: Subscription) -> None:
        self.url = core.stream_url(session_id)
        self.headers = {k: v for k, v in core.headers().items() if k != "Accept"}
        self.subscription = subscription
        self.run_rate_hz: float | None = None  # set while the client asked the session to run
        self.last_step: int | None = None
        self.hello: Hello | None = None
        self.reconnects = 0
        self._resumed = False

    def decode(self, data: bytes | str) -> Hello | Ack | Frame | StreamError:
        """One server message."""
        try:
            msg = unpack(data) if isinstance(data, bytes) else json.loads(data)
            kind = msg["type"]
            if kind == "frame":
                return decode_frame(msg)
            if kind == "ack":
                return Ack.model_validate(msg)
            if kind == "error":
                return StreamError(str(msg["error"]), str(msg["message"]), msg.get("field"))
            if kind == "hello":
                return Hello.model_validate(msg)
        except Exception as err:
            raise ServerError(f"unreadable stream message: {err}") from err
        raise ServerError(f"unknown stream message type {kind!r}")

    def sent(self, msg: dict[str, Any]) -> None:
        """Remember what a reconnect must repeat (running at a rate, or paused)."""
        if msg["type"] == "run":
            self.run_rate_hz = msg["rate_hz"]
        elif msg["type"] == "pause":
            self.run_rate_hz = None

    def on_connected(self, hello: Hello, *, reconnect: bool) -> list[dict[str, Any]]:
        """What to send after ``hello``: the subscription, and ``run`` again after a reconnect."""
        self.hello = hello
        if reconnect:
            self.reconnects += 1
            self._resumed = True
        out = [self.subscription.message()]
        if reconnect and self.run_rate_hz is not None:
            out.append(run_message(self.run_rate_hz))
        return out

    def accept(self, frame: Frame) -> bool:
        """Whether to yield a frame: after a reconnect, the state already seen is skipped."""
        if self._resumed:
            self._resumed = False
            if frame.step == self.last_step:
                return False
        self.last_step = frame.step
        return True

    def close_error(self, code: int | None, reason: str | None) -> DiathermyError | None:
        """The error a close stands for when reconnecting cannot help; None when it may."""
        if code in FINAL_CLOSES:
            message, field, err_code = reason or f"stream closed ({code})", None, None
            try:
                body = json.loads(reason or "")
                message, field, err_code = body["message"], body.get("field"), body.get("error")
            except (ValueError, KeyError, TypeError):
                pass
            return FINAL_CLOSES[code](message, code=err_code, field=field)
        return None

    def closed_error(self, code: int | None, reason: str | None, why: str) -> StreamClosed:
        return StreamClosed(
            f"stream to {self.url} closed ({code}): {why}", close_code=code, reason=reason
        )
