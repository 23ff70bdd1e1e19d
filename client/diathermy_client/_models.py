"""Typed requests and results. JSON shapes mirror the server's OpenAPI schemas (a test checks
that they agree); results carrying arrays are frozen dataclasses of numpy arrays."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict

Dtype = Literal["float16", "float32", "float64"]
WireDtype = Literal["float16", "float32"]
Region = Literal["volume", "top", "surface"]


class _Result(BaseModel):
    """A server answer: unknown keys are kept (newer servers may add some), values are frozen."""

    model_config = ConfigDict(extra="allow", frozen=True)


class _Request(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


# ------------------------------------------------------------------ requests
class SessionCreate(_Request):
    """A new session from a built-in scene name or an inline scene, optionally on another grid."""

    scene: dict[str, Any] | None = None
    builtin: str | None = None
    grid: tuple[int, int, int] | None = None


# Values are checked by the server (one source of truth); its answer names the field.
class StepRequest(_Request):
    n: int = 1


class ElectrodeUpdate(_Request):
    """Electrode changes applied before the next step; None leaves a value unchanged."""

    position_m: tuple[float, float] | None = None
    power_w: float | None = None
    current_density_a_per_m2: float | None = None
    active: bool | None = None
    max_voltage_v: float | None = None  # the generator's voltage limit, V; 0 lifts it


# ------------------------------------------------------------------ results
class Grid(_Result):
    """The node grid: shape (nz, ny, nx), origin and size in m; a uniform grid has a spacing
    (dx, dy, dz) m, a graded one (fine under the electrode) its node coordinates ``axes_m``."""

    shape: tuple[int, int, int]
    spacing_m: tuple[float, float, float] | None = None
    axes_m: list[list[float]] | None = None
    origin_m: tuple[float, float, float]
    size_m: tuple[float, float, float]
    n_nodes: int

    @property
    def is_uniform(self) -> bool:
        """Whether the grid has one spacing per axis (else it is graded: see ``axes_m``)."""
        return self.axes_m is None

    def node_axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Node coordinates along x (nx,), y (ny,), z (nz,) in m, uniform or graded."""
        if self.axes_m is not None:
            return (
                np.asarray(self.axes_m[0]),
                np.asarray(self.axes_m[1]),
                np.asarray(self.axes_m[2]),
            )
        (x0, y0, z0), (lx, ly, lz), (nz, ny, nx) = self.origin_m, self.size_m, self.shape
        return (
            np.linspace(x0, x0 + lx, nx),
            np.linspace(y0, y0 + ly, ny),
            np.linspace(z0, z0 + lz, nz),
        )


class Snapshot(_Result):
    """A saved state of a session, restorable by ``id``."""

    id: str
    step: int
    time_s: float
    created_at: float


class EffectReport(_Result):
    """One effect in one step: whether it ran (else why not), wall time s, solver iterations."""

    ran: bool
    reason: str = ""
    wall_s: float = 0.0
    iterations: int = 0
    extra: dict[str, Any] = {}


class StepReport(_Result):
    """What one step did: per-effect reports, delivered power W, maxima, the cut's volume m^3,
    how far (m) the cut, the vapor and the lesion reach beyond a graded grid's fine region, and
    the effects the scene leaves out that would have acted (name -> why)."""

    step: int
    time_s: float
    effects: dict[str, EffectReport] = {}
    wall_s: float = 0.0
    delivered_power_w: float | None = 0.0
    max_temperature_k: float | None = 0.0
    max_pressure_pa: float | None = 0.0
    max_displacement_m: float | None = 0.0
    max_strain_energy_j_per_m3: float | None = 0.0
    cut_volume_m3: float | None = 0.0
    crater_depth_m: float | None = 0.0
    beyond_fine_region_m: dict[str, float] = {}
    left_out_effects: dict[str, str] = {}
    energy: dict[str, float | None] = {}


class SessionInfo(_Result):
    """A session as the server describes it (``SessionPublic``)."""

    id: str
    scene_name: str
    grid: Grid
    effects: list[str]
    dof_counts: dict[str, int]
    step: int
    time_s: float
    created_at: float
    loaded: bool
    last_report: StepReport | None = None
    snapshots: list[Snapshot] = []


class StepResult(_Result):
    """The reports of the steps one request took, and where the session is now."""

    step: int
    time_s: float
    reports: list[StepReport]


class ElectrodeAck(_Result):
    """An electrode change was accepted; frames with ``control_id`` >= this one reflect it."""

    name: str
    control_id: int


class Electrode(_Result):
    """An electrode at the session's current time: position (x, y) m, drive, the generator's
    voltage limit (V rms, None: none), on/off."""

    name: str
    position_m: tuple[float, float]
    radius_m: float
    drive: Literal["power", "current_density"]
    power_w: float
    current_density_a_per_m2: float
    max_voltage_v: float | None = None
    active: bool
    follows_path: bool
    control_id: int
    step: int
    time_s: float


class Health(_Result):
    status: Literal["ok", "starting"]
    sessions: int = 0


class Scene(_Result):
    """A scene as the server returns it; every key of the server's scene model is kept.

    ``model_dump()`` gives a dict that ``create_session(scene=...)`` accepts back.
    """

    name: str
    description: str = ""
    block_m: tuple[float, float, float]
    grid: tuple[int, int, int]
    dt_s: float
    steps: int
    effects: list[str]
    electrodes: list[dict[str, Any]]


JobKind = Literal["dataset", "training"]
JobState = Literal["queued", "running", "succeeded", "failed", "cancelled"]
FINAL_STATES: frozenset[str] = frozenset({"succeeded", "failed", "cancelled"})


class JobProgress(_Result):
    """How far a job is; fields that do not apply to its kind are None. ``eta_s`` in s."""

    fraction: float = 0.0
    samples: int | None = None
    scenarios: int | None = None
    epoch: int | None = None
    epochs: int | None = None
    train_loss: float | None = None
    val_loss: float | None = None
    val_rel_l2: float | None = None
    eta_s: float | None = None


class Job(_Result):
    """A dataset or training job (``JobPublic``); ``done`` once it reached a final state."""

    id: str
    kind: JobKind
    state: JobState
    spec: dict[str, Any]
    depends_on: str | None = None
    progress: JobProgress
    result: dict[str, Any] | None = None
    error: str | None = None
    attempts: int
    max_attempts: int
    worker: str | None = None
    cancel_requested: bool = False
    created_at: float
    started_at: float | None = None
    finished_at: float | None = None

    @property
    def done(self) -> bool:
        return self.state in FINAL_STATES


class JobLogLine(_Result):
    """One line of a job's log; ``seq`` orders lines (pass the last one as ``after``)."""

    seq: int
    ts: float
    line: str


class ModelInfo(_Result):
    """A registered surrogate (``ModelPublic``): grid (nz, ny, nx), metrics, whether active."""

    name: str
    version: int
    ref: str
    grid: tuple[int, int, int]
    architecture: dict[str, Any]
    dataset_sha256: str
    dataset: dict[str, Any]
    metrics: dict[str, Any]
    training: dict[str, Any]
    created_at: float
    job_id: str | None = None
    active: bool


class ModelList(_Result):
    """Every registered model and the active ``name:version`` per grid key ``NZxNYxNX``."""

    models: list[ModelInfo]
    active: dict[str, str] = {}


@dataclass(frozen=True)
class JobEvent:
    """One server-sent event of a job: ``log`` (``line`` set), ``progress`` or ``end`` (``job``
    set), or ``timeout`` (the server closed the stream; ``data`` has ``after_s``)."""

    event: str
    data: dict[str, Any]
    id: int | None = None

    @property
    def job(self) -> Job | None:
        return Job.model_validate(self.data) if self.event in ("progress", "end") else None

    @property
    def line(self) -> JobLogLine | None:
        return JobLogLine.model_validate(self.data) if self.event == "log" else None


@dataclass(frozen=True)
class Fields:
    """Arrays of one step: nodal (nz, ny, nx[, 3]) or per-tet (n_tets,), with the grid."""

    step: int
    time_s: float
    grid: Grid | None
    arrays: dict[str, np.ndarray]

    def __getitem__(self, name: str) -> np.ndarray:
        return self.arrays[name]


@dataclass(frozen=True)
class Surface:
    """The cut surface: vertices (n, 3) in m and triangles (m, 3); empty before any cut."""

    step: int
    time_s: float
    vertices_m: np.ndarray
    faces: np.ndarray

    @property
    def is_empty(self) -> bool:
        return len(self.faces) == 0


# ------------------------------------------------------------------ stream messages
class Hello(_Result):
    """The first stream message: the session's step and what it offers."""

    type: Literal["hello"]
    session: str
    step: int
    time_s: float
    fields: list[str]
    effects: list[str]
    electrodes: list[str]


class Ack(_Result):
    """The server applied a control message; ``control_id`` orders it against frames."""

    type: Literal["ack"]
    of: str
    step: int | None = None  # the session's step when the message was applied
    control_id: int
    tag: str | int | None = None
    running: bool
    rate_hz: float


@dataclass(frozen=True)
class Frame:
    """One step's state from the stream: fields as numpy arrays, the step report, the surface.

    ``control_id`` is the last control applied before this step; ``dropped`` counts the frames
    the server coalesced away for this client so far (it was reading too slowly).
    """

    session: str
    step: int
    time_s: float
    control_id: int
    dropped: int
    report: StepReport | None
    fields: dict[str, np.ndarray]
    surface: Surface | None = None

    def __getitem__(self, name: str) -> np.ndarray:
        return self.fields[name]
