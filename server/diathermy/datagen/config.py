"""The dataset-generation config (Algorithm 1): grid, material, walk, pressure range, seed."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from diathermy.errors import SceneError
from diathermy.mesh import Grid
from diathermy.physics.materials import Tissue
from diathermy.scene.models import LevelSetConfig

Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]

EXECUTION_FIELDS = frozenset({"workers"})
"""Fields that change how, not what, is generated: left out of the stored generating config."""

GROWABLE_FIELDS = frozenset({"n_scenarios"})
"""Fields a resumed run may change (more scenarios extend the same sequence)."""


class DatagenConfigError(SceneError):
    """A dataset-generation config is invalid; the one-line message names the field."""


class DatagenConfig(BaseModel):
    """What Algorithm 1 generates: ``n_scenarios`` random walks of ``n_steps`` samples each.

    Pressures are absolute, in Pa; tets not yet visited sit at ``material.p_atm_pa``.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    grid: tuple[int, int, int] = Field((17, 17, 33), description="nodes (nz, ny, nx)")
    block_m: tuple[Positive, Positive, Positive] = (0.2, 0.1, 0.1)
    material: Tissue = Tissue()
    n_scenarios: Annotated[int, Field(ge=1)] = 500
    n_steps: Annotated[int, Field(ge=1)] = 400
    p_min_pa: Positive = 101325.0
    # Covers the built-in scenes: measured 101.4 kPa - 2.68 MPa over the fixed-electrode run at
    # 33x33x65 (p99 2.63 MPa; benchmarks/results/paper_scenes.md), 174 kPa for the moving one.
    p_max_pa: Positive = 3.0e6
    perturbation: Annotated[float, Field(ge=0, lt=1, allow_inf_nan=False)] = 0.05
    seed: Annotated[int, Field(ge=0)] = 0
    dt_s: Annotated[float, Field(gt=0, le=10.0, allow_inf_nan=False)] = 0.03
    level_set: LevelSetConfig = LevelSetConfig()
    mechanics_rtol: Annotated[float, Field(gt=0, lt=1)] = 1e-6
    dtype: Literal["float32", "float64"] = "float32"
    workers: Annotated[int, Field(ge=1)] = 1

    @model_validator(mode="after")
    def _consistent(self) -> DatagenConfig:
        if any(n < 3 for n in self.grid):
            raise ValueError(f"grid: every node count must be >= 3, got {self.grid}")
        if not self.p_max_pa > self.p_min_pa:
            raise ValueError(
                f"p_max_pa: must exceed p_min_pa ({self.p_min_pa} Pa), got {self.p_max_pa}"
            )
        if self.p_min_pa < self.material.p_atm_pa:
            raise ValueError(
                f"p_min_pa: must be >= the atmospheric pressure material.p_atm_pa "
                f"({self.material.p_atm_pa} Pa), got {self.p_min_pa}"
            )
        n_surface = 2 * (self.grid[1] - 1) * (self.grid[2] - 1)
        if self.n_scenarios > n_surface:
            raise ValueError(
                f"n_scenarios: each scenario starts from its own top-surface tetrahedron and grid "
                f"{self.grid} has {n_surface}, got {self.n_scenarios}"
            )
        return self

    def make_grid(self) -> Grid:
        """The node grid of the block."""
        return Grid(self.grid, size_m=self.block_m)

    def data_dict(self) -> dict[str, Any]:
        """The generating config: every field that determines the samples (JSON-ready)."""
        return self.model_dump(mode="json", exclude=set(EXECUTION_FIELDS))

    def data_json(self) -> str:
        """``data_dict`` as canonical JSON (sorted keys), stored in the dataset's attributes."""
        return json.dumps(self.data_dict(), sort_keys=True)


def _format_error(err: ValidationError) -> str:
    first = err.errors()[0]
    loc = ".".join(str(p) for p in first["loc"])
    msg = first["msg"].removeprefix("Value error, ")
    if not loc and ": " in msg:  # model-level checks name their field first
        loc, msg = msg.split(": ", 1)
    if not loc:
        return f"datagen config: {msg}"
    return f"datagen config: field '{loc}': {msg}"


def config_from_dict(data: dict[str, Any]) -> DatagenConfig:
    """Validate a plain dict; raises ``DatagenConfigError`` with a one-line message."""
    if not isinstance(data, dict):
        raise DatagenConfigError(
            f"datagen config: must be a mapping of fields, got {type(data).__name__}"
        )
    try:
        return DatagenConfig.model_validate(data)
    except ValidationError as err:
        raise DatagenConfigError(_format_error(err)) from None
    except SceneError as err:  # Tissue's own checks
        raise DatagenConfigError(f"datagen config: {err}") from None


def load_config(path: str | Path) -> DatagenConfig:
    """Read a JSON or YAML datagen config file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise DatagenConfigError(f"datagen config: cannot read {path}: {err.strerror}") from None
    try:
        data = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
    except (json.JSONDecodeError, yaml.YAMLError) as err:
        one_line = " ".join(str(err).split())
        raise DatagenConfigError(f"datagen config: {path} is not valid: {one_line}") from None
    return config_from_dict(data if data is not None else {})
