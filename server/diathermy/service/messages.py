"""The WebSocket stream's messages, as pydantic models (their JSON Schema is the wire contract).

Client to server: JSON text or msgpack binary maps with a ``type``. Server to client: msgpack
binary maps with a ``type`` (``hello``, ``ack``, ``error``, ``frame``).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictBool, TypeAdapter

from diathermy.service.schemas import CurrentDensity, MaxVoltage, Number, PowerW


class _Msg(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Subscribe(_Msg):
    """Choose what frames carry; replaces the previous subscription. Answered by an ``ack``,
    then a frame of the current state (in that order)."""

    type: Literal["subscribe"]
    fields: list[str] = Field(default_factory=list, max_length=16)
    every: int = Field(1, ge=1, le=10_000, description="send every k-th step")
    dtype: Literal["float16", "float32"] = "float32"
    region: Literal["volume", "top", "surface"] = Field(
        "volume",
        description="whole grid (nz, ny, nx[, 3]); its top node layer, the tissue's top face "
        "(ny, nx[, 3]: 1/nz of the bytes); or the cut surface with fields sampled on it",
    )


class ElectrodeControl(_Msg):
    """Move or re-drive an electrode before the next step; omitted values stay."""

    type: Literal["electrode"]
    name: str = "active"
    position_m: tuple[Number, Number] | None = Field(
        None, description="(x, y) on the top surface, m, within the block"
    )
    power_w: PowerW | None = None
    current_density_a_per_m2: CurrentDensity | None = None
    max_voltage_v: MaxVoltage | None = Field(
        None, description="generator voltage limit, V rms (0 lifts it)"
    )
    active: StrictBool | None = None
    tag: str | int | None = Field(None, description="echoed in the ack")


class Run(_Msg):
    """Step continuously at (at most) ``rate_hz`` steps per second."""

    type: Literal["run"]
    rate_hz: float = Field(10.0, gt=0, allow_inf_nan=False)


class Pause(_Msg):
    """Stop stepping continuously."""

    type: Literal["pause"]


class Step(_Msg):
    """Take ``n`` steps now (also while paused); steps queued at once are bounded by the server's
    ``MAX_STEPS_PER_REQUEST`` (200 by default), the same limit as a REST step request."""

    type: Literal["step"]
    n: int = Field(1, ge=1, description="at most MAX_STEPS_PER_REQUEST queued at once")


ClientMessage = Annotated[
    Subscribe | ElectrodeControl | Run | Pause | Step, Field(discriminator="type")
]
client_message: TypeAdapter[Any] = TypeAdapter(ClientMessage)


class WireArray(BaseModel):
    """An array: C-order raw bytes in little-endian ``dtype`` ('<f2', '<f4', '<i4', ...)."""

    shape: list[int]
    dtype: str
    data: bytes


class Hello(BaseModel):
    type: Literal["hello"]
    session: str
    step: int
    time_s: float
    fields: list[str]
    effects: list[str]
    electrodes: list[str]


class Ack(BaseModel):
    type: Literal["ack"]
    of: str = Field(description="the acknowledged message type")
    step: int | None = Field(
        description="the session's step when the message was applied (an electrode change "
        "takes effect from step + 1)"
    )
    control_id: int = Field(description="frames with control_id >= this reflect the message")
    tag: str | int | None = None
    running: bool
    rate_hz: float


class ErrorMessage(BaseModel):
    type: Literal["error"]
    error: str
    message: str
    field: str | None = None


class SurfaceArrays(BaseModel):
    vertices: WireArray = Field(description="(n, 3) positions in m")
    faces: WireArray = Field(description="(m, 3) int32 vertex indices")


class FrameMessage(BaseModel):
    """One step's state; volume fields are (nz, ny, nx[, 3]) or per-tet (n_tets,)."""

    type: Literal["frame"]
    session: str
    step: int
    time_s: float
    control_id: int = Field(description="the last control message applied before this step")
    dropped: int = Field(description="frames this client missed because it was slow, so far")
    report: dict[str, Any] | None
    fields: dict[str, WireArray]
    surface: SurfaceArrays | None = Field(None, description="present when region is 'surface'")


ServerMessage = Annotated[Hello | Ack | ErrorMessage | FrameMessage, Field(discriminator="type")]


def stream_messages_schema() -> dict[str, Any]:
    """JSON Schema of both directions of the stream."""
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": "https://diathermy.dev/schema/stream-messages-v1.json",
        "title": "diathermy stream messages (v1)",
        "description": "Messages of /v1/sessions/{id}/stream. Client messages are JSON text or "
        "msgpack binary; server messages are msgpack binary ('bytes' values are msgpack bin). "
        "Every close the server makes is preceded by an 'error' message and has the same error "
        "as a JSON close reason, except 1009, which the WebSocket layer sends with a plain-text "
        "reason (see x-close-codes).",
        "x-close-codes": {
            "1008": "too_many_messages: over 64 replies unread (control messages flood)",
            "1009": "a message over MAX_MESSAGE_BYTES (plain-text reason, no error message)",
            "1011": "the session could not be loaded, e.g. checkpoint_error",
            "4400": "bad_message: not JSON/msgpack, unknown type, invalid or out-of-range value",
            "4401": "unauthorized: missing or unknown token",
            "4404": "not_found: no such session for this token, or it was deleted",
        },
        "client_to_server": TypeAdapter(ClientMessage).json_schema(),
        "server_to_client": TypeAdapter(ServerMessage).json_schema(),
    }
