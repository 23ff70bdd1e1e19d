"""Everything that does no I/O, shared by ``Client`` and ``AsyncClient``: URLs, the auth header,
request bodies, (de)serialisation of msgpack/npz/JSON answers, error mapping, retry policy.

Each endpoint is a ``Call``: the request to send and a function that turns the raw answer into a
typed result. The clients only move bytes.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar
from urllib.parse import quote

import msgpack
import numpy as np

from diathermy_client._errors import DiathermyError, ServerError, error_for
from diathermy_client._models import (
    Dtype,
    Electrode,
    ElectrodeAck,
    ElectrodeUpdate,
    Fields,
    Grid,
    Health,
    Job,
    JobEvent,
    JobLogLine,
    ModelInfo,
    ModelList,
    Scene,
    SessionCreate,
    SessionInfo,
    Snapshot,
    StepRequest,
    StepResult,
    Surface,
)

T = TypeVar("T")

DEFAULT_URL = "http://127.0.0.1:8000"
IDEMPOTENT = frozenset({"GET", "HEAD", "PUT", "DELETE", "OPTIONS"})
RETRY_STATUSES = frozenset({502, 503, 504})


@dataclass(frozen=True)
class Request:
    """One HTTP request, relative to the base URL."""

    method: str
    path: str
    params: dict[str, str] | None = None
    json: Any = None

    @property
    def idempotent(self) -> bool:
        return self.method in IDEMPOTENT


@dataclass(frozen=True)
class Response:
    """The parts of an HTTP answer the SDK reads."""

    status: int
    content: bytes
    content_type: str = ""


@dataclass(frozen=True)
class Call(Generic[T]):
    """A request and how to read its successful answer."""

    request: Request
    parse: Callable[[Response], T]
    ok_if_missing_on_retry: bool = False  # DELETE: a 404 after a lost answer means done


@dataclass(frozen=True)
class RetryPolicy:
    """Retries of idempotent calls (GET/PUT/DELETE) on transport errors and 502/503/504.

    Delays grow ``backoff_s * 2**k`` up to ``max_backoff_s``.
    """

    retries: int = 3
    backoff_s: float = 0.2
    max_backoff_s: float = 5.0

    def delays(self) -> Iterator[float]:
        for k in range(self.retries):
            yield min(self.max_backoff_s, self.backoff_s * 2**k)


# ------------------------------------------------------------------ wire helpers
def unpack(data: bytes) -> Any:
    """A msgpack message (bytes stay bytes, strings are str)."""
    return msgpack.unpackb(data, raw=False)


def pack(obj: Any) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


def decode_array(d: dict[str, Any]) -> np.ndarray:
    """``{"shape", "dtype", "data"}`` (C-order little-endian bytes) -> a read-only array."""
    return np.frombuffer(d["data"], dtype=np.dtype(d["dtype"])).reshape(d["shape"])


def json_body(resp: Response) -> Any:
    try:
        return json.loads(resp.content)
    except ValueError:
        raise ServerError(
            f"expected JSON, got {resp.content[:200]!r}", status=resp.status
        ) from None


def check(resp: Response) -> None:
    """Raise the SDK error for an error status (the body is ``{"error", "message", "field"}``)."""
    if resp.status < 400:
        return
    try:
        body: Any = json.loads(resp.content)
    except ValueError:
        body = resp.content.decode("utf-8", "replace")
    raise error_for(resp.status, body)


def _seg(value: str) -> str:
    return quote(str(value), safe="")


def _fields_param(names: Sequence[str] | str) -> str:
    names = [names] if isinstance(names, str) else list(names)
    if not names:
        raise ValueError("name at least one field")
    return ",".join(names)


def parse_fields_msgpack(resp: Response) -> Fields:
    msg = unpack(resp.content)
    grid = Grid.model_validate(msg["grid"]) if msg.get("grid") else None
    arrays = {n: decode_array(a) for n, a in msg["fields"].items()}
    return Fields(step=int(msg["step"]), time_s=float(msg["time_s"]), grid=grid, arrays=arrays)


def parse_fields_npz(resp: Response) -> Fields:
    with np.load(io.BytesIO(resp.content)) as npz:
        arrays = {k: npz[k] for k in npz.files if k not in ("step", "time_s")}
        step, time_s = int(npz["step"]), float(npz["time_s"])
    return Fields(step=step, time_s=time_s, grid=None, arrays=arrays)


def parse_surface_msgpack(resp: Response) -> Surface:
    msg = unpack(resp.content)
    verts = decode_array(msg["vertices_m"]).reshape(-1, 3)
    faces = decode_array(msg["faces"]).reshape(-1, 3)
    return Surface(int(msg["step"]), float(msg["time_s"]), verts, faces)


# ------------------------------------------------------------------ the core
@dataclass
class ClientCore:
    """Base URL, token, timeout and retry policy, and one ``Call`` per endpoint.

    ``base_url`` defaults to ``$DIATHERMY_URL`` (else http://127.0.0.1:8000) and ``token`` to
    ``$DIATHERMY_TOKEN``.
    """

    base_url: str | None = None
    token: str | None = None
    timeout_s: float = 30.0
    retry: RetryPolicy = field(default_factory=RetryPolicy)

    def __post_init__(self) -> None:
        self.base_url = (self.base_url or os.environ.get("DIATHERMY_URL") or DEFAULT_URL).rstrip(
            "/"
        )
        if self.token is None:
            self.token = os.environ.get("DIATHERMY_TOKEN") or None

    # --- what every request carries
    def headers(self) -> dict[str, str]:
        out = {"User-Agent": "diathermy-client", "Accept": "application/json"}
        if self.token:
            out["Authorization"] = f"Bearer {self.token}"
        return out

    def stream_url(self, session_id: str) -> str:
        assert self.base_url is not None
        scheme, rest = self.base_url.split("://", 1)
        ws = {"http": "ws", "https": "wss"}.get(scheme, scheme)
        return f"{ws}://{rest}/v1/sessions/{_seg(session_id)}/stream"

    # --- endpoints
    def health(self) -> Call[Health]:
        return Call(Request("GET", "/healthz"), lambda r: Health.model_validate(json_body(r)))

    def ready(self) -> Call[Health]:
        return Call(Request("GET", "/readyz"), lambda r: Health.model_validate(json_body(r)))

    def list_scenes(self) -> Call[dict[str, Scene]]:
        return Call(
            Request("GET", "/v1/scenes"),
            lambda r: {k: Scene.model_validate(v) for k, v in json_body(r).items()},
        )

    def create_session(
        self,
        builtin: str | None = None,
        *,
        scene: dict[str, Any] | Scene | None = None,
        grid: tuple[int, int, int] | None = None,
    ) -> Call[SessionInfo]:
        if isinstance(scene, Scene):
            scene = scene.model_dump()
        if builtin is None and scene is None:
            builtin = "default"
        body = SessionCreate(builtin=builtin, scene=scene, grid=grid)
        return Call(
            Request("POST", "/v1/sessions", json=body.model_dump(exclude_none=True)),
            _session_info,
        )

    def list_sessions(self) -> Call[list[SessionInfo]]:
        return Call(
            Request("GET", "/v1/sessions"),
            lambda r: [SessionInfo.model_validate(s) for s in json_body(r)["sessions"]],
        )

    def get_session(self, session_id: str) -> Call[SessionInfo]:
        return Call(Request("GET", f"/v1/sessions/{_seg(session_id)}"), _session_info)

    def delete_session(self, session_id: str) -> Call[None]:
        return Call(
            Request("DELETE", f"/v1/sessions/{_seg(session_id)}"),
            lambda r: None,
            ok_if_missing_on_retry=True,
        )

    def step(self, session_id: str, n: int = 1) -> Call[StepResult]:
        body = StepRequest(n=n)
        return Call(
            Request("POST", f"/v1/sessions/{_seg(session_id)}/step", json=body.model_dump()),
            lambda r: StepResult.model_validate(json_body(r)),
        )

    def update_electrode(
        self, session_id: str, name: str = "active", **changes: Any
    ) -> Call[ElectrodeAck]:
        body = ElectrodeUpdate(**changes).model_dump(exclude_none=True)
        if not body:
            raise ValueError(
                "give at least one of position_m, power_w, current_density_a_per_m2, active, "
                "max_voltage_v"
            )
        return Call(
            Request("PATCH", f"/v1/sessions/{_seg(session_id)}/electrodes/{_seg(name)}", json=body),
            lambda r: ElectrodeAck.model_validate(json_body(r)),
        )

    def list_electrodes(self, session_id: str) -> Call[list[Electrode]]:
        return Call(
            Request("GET", f"/v1/sessions/{_seg(session_id)}/electrodes"),
            lambda r: [Electrode.model_validate(e) for e in json_body(r)["electrodes"]],
        )

    def get_electrode(self, session_id: str, name: str = "active") -> Call[Electrode]:
        return Call(
            Request("GET", f"/v1/sessions/{_seg(session_id)}/electrodes/{_seg(name)}"),
            lambda r: Electrode.model_validate(json_body(r)),
        )

    def read_fields(
        self,
        session_id: str,
        names: Sequence[str] | str,
        *,
        dtype: Dtype = "float32",
        format: str = "msgpack",
    ) -> Call[Fields]:
        if format not in ("msgpack", "npz"):
            raise ValueError(f"format must be 'msgpack' or 'npz', got {format!r}")
        params = {"fields": _fields_param(names), "dtype": dtype, "format": format}
        parse = parse_fields_msgpack if format == "msgpack" else parse_fields_npz
        return Call(Request("GET", f"/v1/sessions/{_seg(session_id)}/fields", params), parse)

    def read_surface(self, session_id: str) -> Call[Surface]:
        return Call(
            Request("GET", f"/v1/sessions/{_seg(session_id)}/surface", {"format": "msgpack"}),
            parse_surface_msgpack,
        )

    def read_vtu(self, session_id: str) -> Call[bytes]:
        return Call(Request("GET", f"/v1/sessions/{_seg(session_id)}/vtu"), lambda r: r.content)

    def take_snapshot(self, session_id: str) -> Call[Snapshot]:
        return Call(
            Request("POST", f"/v1/sessions/{_seg(session_id)}/snapshots"),
            lambda r: Snapshot.model_validate(json_body(r)),
        )

    def list_snapshots(self, session_id: str) -> Call[list[Snapshot]]:
        return Call(
            Request("GET", f"/v1/sessions/{_seg(session_id)}/snapshots"),
            lambda r: [Snapshot.model_validate(s) for s in json_body(r)],
        )

    def restore_snapshot(self, session_id: str, snapshot: str | Snapshot) -> Call[SessionInfo]:
        sid = snapshot.id if isinstance(snapshot, Snapshot) else snapshot
        return Call(
            Request("POST", f"/v1/sessions/{_seg(session_id)}/snapshots/{_seg(sid)}/restore"),
            _session_info,
        )

    # --- jobs
    def submit_job(self, spec: dict[str, Any]) -> Call[Job]:
        if not isinstance(spec, dict):
            raise TypeError(f"spec must be a dict with a 'kind', got {type(spec).__name__}")
        return Call(Request("POST", "/v1/jobs", json=spec), _job)

    def list_jobs(self, *, state: str | None = None, kind: str | None = None) -> Call[list[Job]]:
        params = {k: v for k, v in (("state", state), ("kind", kind)) if v is not None}
        return Call(
            Request("GET", "/v1/jobs", params or None),
            lambda r: [Job.model_validate(j) for j in json_body(r)["jobs"]],
        )

    def get_job(self, job_id: str) -> Call[Job]:
        return Call(Request("GET", f"/v1/jobs/{_seg(job_id)}"), _job)

    def cancel_job(self, job_id: str) -> Call[Job]:
        return Call(Request("POST", f"/v1/jobs/{_seg(job_id)}/cancel"), _job)

    def job_log(self, job_id: str, *, after: int = 0) -> Call[list[JobLogLine]]:
        return Call(
            Request("GET", f"/v1/jobs/{_seg(job_id)}/log", {"after": str(int(after))}),
            lambda r: [JobLogLine.model_validate(x) for x in json_body(r)["lines"]],
        )

    def job_events(self, job_id: str, *, timeout_s: float = 600.0) -> Request:
        """The request of a job's event stream (read as server-sent events, not retried)."""
        return Request("GET", f"/v1/jobs/{_seg(job_id)}/events", {"timeout_s": str(timeout_s)})

    # --- model registry
    def list_models(self) -> Call[ModelList]:
        return Call(Request("GET", "/v1/models"), lambda r: ModelList.model_validate(json_body(r)))

    def get_model(self, name: str, version: int) -> Call[ModelInfo]:
        return Call(Request("GET", f"/v1/models/{_seg(name)}/{int(version)}"), _model)

    def activate_model(self, name: str, version: int) -> Call[ModelInfo]:
        return Call(Request("POST", f"/v1/models/{_seg(name)}/{int(version)}/activate"), _model)

    # --- reading answers
    def result(self, call: Call[T], resp: Response, *, retried: bool = False) -> T:
        """The typed result of an answer, or the SDK error it stands for."""
        if call.ok_if_missing_on_retry and retried and resp.status == 404:
            return call.parse(resp)
        check(resp)
        try:
            return call.parse(resp)
        except DiathermyError:
            raise
        except Exception as err:  # a body that does not match the contract
            raise ServerError(
                f"unreadable answer to {call.request.method} {call.request.path}: {err}",
                status=resp.status,
            ) from err

    def should_retry(self, call: Call[Any], status: int | None) -> bool:
        """Whether to retry a call after a transport error (status None) or this status."""
        return call.request.idempotent and (status is None or status in RETRY_STATUSES)


def _session_info(resp: Response) -> SessionInfo:
    return SessionInfo.model_validate(json_body(resp))


def _job(resp: Response) -> Job:
    return Job.model_validate(json_body(resp))


def _model(resp: Response) -> ModelInfo:
    return ModelInfo.model_validate(json_body(resp))


@dataclass
class SSEParser:
    """Server-sent events line by line: ``feed`` each line (no newline); a blank line ends an
    event and returns it (``data`` parsed as JSON), other lines return None."""

    event: str = "message"
    data: list[str] = field(default_factory=list)
    id: int | None = None

    def feed(self, line: str) -> JobEvent | None:
        if line == "":
            if not self.data:
                self.event, self.id = "message", None
                return None
            raw = "\n".join(self.data)
            try:
                data = json.loads(raw)
            except ValueError:
                raise ServerError(f"unreadable event data {raw[:200]!r}") from None
            out = JobEvent(self.event, data if isinstance(data, dict) else {"value": data}, self.id)
            self.event, self.data, self.id = "message", [], None
            return out
        name, _, value = line.partition(":")
        value = value.removeprefix(" ")
        if name == "event":
            self.event = value
        elif name == "data":
            self.data.append(value)
        elif name == "id" and value.isdigit():
            self.id = int(value)
        return None  # comments (":...") and unknown fields are ignored, as the spec says
