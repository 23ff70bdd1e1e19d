"""diathermy_client: the Python SDK of the diathermy simulation service.

Blocking and asyncio clients over one core, typed results with numpy arrays, a WebSocket stream
with controls and reconnects, and a documented exception tree. Needs only httpx, websockets,
msgpack, numpy and pydantic.

Example::

    from diathermy_client import Client

    with Client("http://127.0.0.1:8000", token="secret") as client:
        session = client.create_session("moving-electrode", grid=(9, 9, 17))
        session.step(10)
        phi = session.field("level_set")  # (nz, ny, nx) in m
"""

from diathermy_client._async import AsyncClient, AsyncSession
from diathermy_client._async_stream import AsyncStream
from diathermy_client._errors import (
    AuthError,
    Conflict,
    DiathermyError,
    InvalidRequest,
    LimitExceeded,
    NotFound,
    ServerError,
    StreamClosed,
    Timeout,
    TransportError,
)
from diathermy_client._models import (
    Ack,
    EffectReport,
    Electrode,
    ElectrodeAck,
    Fields,
    Frame,
    Grid,
    Health,
    Hello,
    Job,
    JobEvent,
    JobLogLine,
    JobProgress,
    ModelInfo,
    ModelList,
    Scene,
    SessionInfo,
    Snapshot,
    StepReport,
    StepResult,
    Surface,
)
from diathermy_client._stream_core import ReconnectPolicy
from diathermy_client._sync import Client, Session
from diathermy_client._sync_stream import Stream

__version__ = "0.1.0"

__all__ = [
    "Ack",
    "AsyncClient",
    "AsyncSession",
    "AsyncStream",
    "AuthError",
    "Client",
    "Conflict",
    "DiathermyError",
    "EffectReport",
    "Electrode",
    "ElectrodeAck",
    "Fields",
    "Frame",
    "Grid",
    "Health",
    "Hello",
    "InvalidRequest",
    "Job",
    "JobEvent",
    "JobLogLine",
    "JobProgress",
    "LimitExceeded",
    "ModelInfo",
    "ModelList",
    "NotFound",
    "ReconnectPolicy",
    "Scene",
    "ServerError",
    "Session",
    "SessionInfo",
    "Snapshot",
    "StepReport",
    "StepResult",
    "Stream",
    "StreamClosed",
    "Surface",
    "Timeout",
    "TransportError",
    "__version__",
]
