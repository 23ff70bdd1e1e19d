"""Request and response models of the REST API (the ``SessionCreate``/``SessionPublic`` family)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictBool, model_validator

from diathermy.scene import Scene
from diathermy.service.limits import MAX_CURRENT_DENSITY_A_PER_M2, MAX_POWER_W, MAX_VOLTAGE_V

Number = Annotated[float, Field(strict=True)]
"""A JSON number (an integer is one); a bool or a numeric string is refused, not coerced."""

PowerW = Annotated[Number, Field(ge=0, le=MAX_POWER_W, allow_inf_nan=False)]
"""An electrode's set power, W (REST and stream controls)."""
CurrentDensity = Annotated[
    Number, Field(ge=0, le=MAX_CURRENT_DENSITY_A_PER_M2, allow_inf_nan=False)
]
"""An electrode's set current density, A/m^2."""
MaxVoltage = Annotated[Number, Field(ge=0, le=MAX_VOLTAGE_V, allow_inf_nan=False)]
"""The generator's voltage limit, V rms; 0 lifts it."""


class _In(BaseModel):
    model_config = ConfigDict(extra="forbid")


class SessionCreate(_In):
    """A new session from an inline scene or a built-in scene name, optionally on another grid."""

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={
            "examples": [{"builtin": "default", "grid": [5, 5, 9]}],
            "oneOf": [{"required": ["scene"]}, {"required": ["builtin"]}],
        },
    )

    scene: Scene | None = Field(None, description="an inline scene")
    builtin: str | None = Field(None, description="a built-in scene name, e.g. 'default'")
    grid: tuple[int, int, int] | None = Field(
        None, description="override the scene's grid, nodes (nz, ny, nx)"
    )

    @model_validator(mode="after")
    def _one_source(self) -> SessionCreate:
        if (self.scene is None) == (self.builtin is None):
            raise ValueError("give exactly one of 'scene' and 'builtin'")
        return self


class GridPublic(BaseModel):
    shape: tuple[int, int, int] = Field(description="nodes (nz, ny, nx)")
    spacing_m: tuple[float, float, float] | None = Field(
        description="(dx, dy, dz) in m of a uniform grid; null on a graded grid (see axes_m)"
    )
    axes_m: list[list[float]] | None = Field(
        None,
        min_length=3,
        max_length=3,
        description="node coordinates [x (nx,), y (ny,), z (nz,)] in m of a graded grid; null on "
        "a uniform grid",
    )
    origin_m: tuple[float, float, float]
    size_m: tuple[float, float, float]
    n_nodes: int


class SnapshotPublic(BaseModel):
    id: str
    step: int
    time_s: float
    created_at: float


class SessionPublic(BaseModel):
    """A session as clients see it."""

    id: str
    scene_name: str
    grid: GridPublic
    effects: list[str]
    dof_counts: dict[str, int]
    step: int
    time_s: float
    created_at: float
    loaded: bool = Field(description="whether the simulation is in memory (else on disk)")
    last_report: dict[str, Any] | None = None
    snapshots: list[SnapshotPublic] = []


class SessionList(BaseModel):
    sessions: list[SessionPublic]


class StepRequest(_In):
    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"n": 2}]})

    n: int = Field(
        1,
        ge=1,
        description="steps to take; at most the server's MAX_STEPS_PER_REQUEST (200 by default), "
        "else 422 limit_exceeded",
    )


class StepResult(BaseModel):
    step: int
    time_s: float
    reports: list[dict[str, Any]]


class ElectrodeUpdate(_In):
    """Run-time changes to one electrode, applied before the next step; omitted means unchanged."""

    position_m: tuple[Number, Number] | None = Field(
        None, description="(x, y) on the top surface, m, within the block"
    )
    power_w: PowerW | None = Field(None, description="W; switches to power drive")
    current_density_a_per_m2: CurrentDensity | None = Field(
        None, description="A/m^2; switches to current-density drive"
    )
    max_voltage_v: MaxVoltage | None = Field(
        None,
        description="generator voltage limit, V rms (0 lifts it): where the drive would need "
        "more, the electrode is held at it and delivers V^2 / R",
    )
    active: StrictBool | None = None


class ElectrodeAck(BaseModel):
    name: str
    control_id: int = Field(description="stream frames with control_id >= this reflect the change")


Triple = Annotated[list[float], Field(min_length=3, max_length=3)]
IndexTriple = Annotated[list[int], Field(min_length=3, max_length=3)]


class SurfacePublic(BaseModel):
    """The cut surface as a triangle mesh (empty when nothing is cut).

    In msgpack (``format=msgpack``) ``vertices_m`` and ``faces`` are wire arrays
    ``{shape, dtype, data}`` ((n, 3) float64 and (m, 3) int32), named as here.
    """

    step: int
    time_s: float
    vertices_m: list[Triple] = Field(description="(n, 3) vertex positions, m")
    faces: list[IndexTriple] = Field(description="(m, 3) vertex indices of the triangles")


class ErrorPublic(BaseModel):
    """Every error response: a machine-readable code, a message, and the offending field."""

    error: str = Field(description="error code, e.g. 'scene_error', 'limit_exceeded'")
    message: str
    field: str | None = None


class Health(BaseModel):
    status: Literal["ok", "starting"]
    sessions: int = 0


FieldFormat = Literal["msgpack", "npz"]
FieldDtype = Literal["float16", "float32", "float64"]
