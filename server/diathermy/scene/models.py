"""The scene model (schema version 1): every input of a simulation, validated, with SI units."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from diathermy.errors import MeshError
from diathermy.mesh import Grid
from diathermy.physics.levelset_law import (
    CFL,
    NONLOCAL_LENGTH_M,
    REINIT_EVERY,
    V0_M_PER_S,
    LevelSetLaw,
)
from diathermy.physics.materials import Tissue
from diathermy.scene.resolution import (
    MAX_GRADED_NODES,
    Box,
    Resolution,
    graded_grid,
    resolved_region,
)

SCHEMA_VERSION: Literal[1] = 1

EFFECTS = (
    "electric",
    "thermal",
    "vaporization",
    "mechanics",
    "dissection",
    "desiccation",
    "thermal_damage",
)
"""Effects a scene can call for, in the order a step runs them."""

Effect = Literal[
    "electric",
    "thermal",
    "vaporization",
    "mechanics",
    "dissection",
    "desiccation",
    "thermal_damage",
]

DEFAULT_EFFECTS: tuple[Effect, ...] = (
    "electric",
    "thermal",
    "vaporization",
    "mechanics",
    "dissection",
)

REQUIRES: dict[str, tuple[str, ...]] = {
    "electric": (),
    "thermal": (),
    "vaporization": ("thermal",),
    "mechanics": ("vaporization",),
    "dissection": ("mechanics",),
    "desiccation": ("electric", "vaporization"),
    "thermal_damage": ("thermal",),
}
"""What each effect needs; ``close_effects`` adds these transitively."""

Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]


def close_effects(effects: Sequence[str]) -> tuple[str, ...]:
    """The effects plus everything they need, in run order."""
    wanted = set(effects)
    stack = list(effects)
    while stack:
        for dep in REQUIRES[stack.pop()]:
            if dep not in wanted:
                wanted.add(dep)
                stack.append(dep)
    return tuple(e for e in EFFECTS if e in wanted)


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ElectrodePath(_Model):
    """A path on the top surface followed at constant speed from ``start_s``; it stops at the end."""

    waypoints_m: list[tuple[Finite, Finite]] = Field(min_length=2, description="(x, y) in m")
    speed_m_per_s: Positive = 12.35e-3
    kind: Literal["polyline", "spline"] = "polyline"
    start_s: NonNegative = 0.0


class Electrode(_Model):
    """The active ball electrode: where it touches, how it is driven, when it is on."""

    name: str = "active"
    position_m: tuple[Finite, Finite] = Field(
        (0.1, 0.05), description="(x, y) of the contact centre on the top surface, m"
    )
    radius_m: Positive = 1.17e-3
    contact: Literal["flat", "draped"] = Field(
        "flat",
        description="in a crater, the contact disk lies flat at the healthy surface's height "
        "under its centre ('flat'), or follows that surface under each of its points ('draped')",
    )
    drive: Literal["current_density", "power"] = "power"
    current_density_a_per_m2: NonNegative = 5.72e4
    power_w: NonNegative = 50.0
    max_voltage_v: Positive | None = Field(
        None,
        description="the generator's output limit, V rms: where the set power or current density "
        "would need more, the electrode is held at this voltage and delivers V^2 / R, so the "
        "power falls as the tissue's resistance R rises (a generator's power curve); null: none",
    )
    active: bool = True
    schedule_s: list[tuple[NonNegative, NonNegative]] | None = Field(
        None, description="on-intervals [(t_on, t_off), ...] in s; None means always on"
    )
    path: ElectrodePath | None = None

    @field_validator("schedule_s")
    @classmethod
    def _ordered(cls, v: list[tuple[float, float]] | None) -> list[tuple[float, float]] | None:
        for t_on, t_off in v or []:
            if t_off <= t_on:
                raise ValueError(f"on-interval ({t_on}, {t_off}) must end after it starts")
        return v


class SolverConfig(_Model):
    """Accuracy knobs of the electro-thermal solves."""

    electric_rtol: Annotated[float, Field(gt=0, lt=1)] = 1e-9
    electric_energy_tolerance: Annotated[float, Field(gt=0, lt=1)] | None = Field(
        1e-5,
        description="incremental: the potential is accepted once PCG from the last one with "
        "the kept AMG hierarchy estimates its relative energy-norm error at most this (the "
        "power it delivers to ~its square), else solved to electric_rtol; null: always to "
        "electric_rtol",
    )
    electric_window_m: Annotated[float, Field(ge=0, le=1)] = Field(
        2e-3,
        description="incremental: before that PCG the last potential is corrected exactly "
        "(sparse LU) on the nodes around its residual grown by this margin in m, halved "
        "until at most 4000 nodes; 0: no window (the accuracy is the energy tolerance's "
        "either way)",
    )
    thermal_rtol: Annotated[float, Field(gt=0, lt=1)] = 1e-9
    coupling: Literal["staggered", "monolithic"] = "staggered"
    incremental: bool = Field(
        True,
        description="each step costs what changed: the mechanics starts from its predictor "
        "(mechanics.predictor) and solves in full only when the residual check or the interval "
        "asks for it; false solves every effect in full every step (the reference)",
    )


class MechanicsConfig(_Model):
    """Which backend solves the mechanics and its accuracy knobs."""

    backend: Literal["fem", "cnn", "pgd"] = "fem"
    rtol: Annotated[float, Field(gt=0, lt=1)] = 1e-6
    model: str | None = Field(None, description="surrogate model path or registry name")
    predictor: Literal["previous", "none", "auto"] = Field(
        "previous",
        description="fem, incremental: 'previous' starts from the last displacement, Ritz-scaled "
        "and patch-corrected, accepted when its relative residual is at most guard_tolerance "
        "(default 1e-2), else solved in full; 'auto' starts from the network (mechanics.model, "
        "else the grid's shipped CNN) where persistence has nothing (first mechanics step) or "
        "its residual exceeds 0.5 (a jump), persistence otherwise, and falls back to "
        "persistence with the reason in the step report when the grid has no model; 'none' "
        "solves in full every step. The step report names the predictor (extra.predictor, "
        "extra.predictor_why)",
    )
    full_every: Annotated[int, Field(ge=1, le=10000)] = Field(
        10, description="fem predictor 'previous': a full solve at least every this many solves"
    )
    interval_tolerance: Annotated[float, Field(ge=0, lt=1)] = Field(
        3e-4,
        description="fem, incremental: the interval's full solve (every full_every solves) is "
        "PCG on the whole block with the kept AMG hierarchy, from the step's local answer, "
        "until the estimated relative energy-norm error is at most this (a tenth of "
        "energy_tolerance by default: the far-field error built up since the last one is "
        "reset); 0: CG to the FEM tolerance (rtol), as in the full mode",
    )
    guard_tolerance: Annotated[float, Field(gt=0)] | None = Field(
        None,
        description="cnn: relative equilibrium residual above which the prediction is corrected "
        "by CG; fem with predictor 'previous': above which it is solved in full; pgd: "
        "estimated strain-energy error above which a mode is enriched online",
    )
    guard: Literal["auto", "residual", "energy"] = Field(
        "auto",
        description="fem, incremental: what accepts the predictor's answer without a full "
        "solve. 'residual': its relative residual after the patch is at most guard_tolerance; "
        "'energy': only PCG with the kept AMG hierarchy from it (at most polish_iterations) "
        "until the estimated relative energy-norm error is at most energy_tolerance. With "
        "'residual' a step that fails the residual check is polished the same way before it "
        "falls back to the full solve. 'auto': 'energy' on graded grids (where a small residual "
        "let 57 % strain-energy errors through) unless guard_tolerance is set, 'residual' on "
        "uniform grids",
    )
    energy_tolerance: Annotated[float, Field(gt=0, lt=1)] = Field(
        1e-3,
        description="fem, incremental: relative energy-norm error estimate sqrt(r.Mr)/||u||_K "
        "a polished answer must reach (M a V-cycle of the kept hierarchy: the estimate reads "
        "0.2-0.5x the true error on the built-in graded grids, so 1e-3 admits about 3e-3; 3e-3 "
        "let whole runs leave the full solve's trajectory after 25-92 steps)",
    )
    polish_iterations: Annotated[int, Field(ge=0, le=100)] = Field(
        20,
        description="fem, incremental: PCG iterations with the kept hierarchy before the step "
        "is solved in full (0: no polish)",
    )
    polish_window_m: Annotated[float, Field(ge=0, le=1)] = Field(
        0.016,
        description="fem, incremental: the polish first solves on a window of nodes around the "
        "patch grown by this margin in m (halved until the window holds at most a quarter of "
        "the nodes), the rest held, with its own kept AMG hierarchy; the global energy check "
        "follows (0: no window, the whole block)",
    )
    window_history: Annotated[int, Field(ge=0, le=16)] = Field(
        0,
        description="fem, incremental: the window's PCG also solves for a combination of the "
        "last this many displacements (global vectors, one block product a step), so that the "
        "far field the window holds follows the run's own shapes: on the fixed electrode's "
        "0.4 mm grid the global polish then took 0-1 PCG iterations instead of 4-12, but a "
        "100-step run left the full solve's trajectory at step 96, and with energy_tolerance "
        "5e-4 the moving electrode's at step 24 (0: the window alone, the default)",
    )
    correction: Literal["none", "patch"] = Field(
        "patch",
        description="cnn and fem-previous/auto: 'patch' solves equilibrium exactly on the nodes "
        "where the prediction's residual concentrates (the crater wall), the prediction held "
        "fixed around them; 'none' keeps the Ritz-scaled prediction, and (fem-incremental) "
        "also drops the polish window, which is placed around the patch: the polish is then "
        "global PCG only (1.8x slower a step on the default grid). pgd ignores it",
    )
    patch_threshold: Annotated[float, Field(gt=0, le=1)] = Field(
        0.1,
        description="cnn and fem-previous patch: seed nodes whose residual force reaches "
        "this x its peak",
    )
    patch_layers: Annotated[int, Field(ge=0, le=8)] = Field(
        2, description="cnn and fem-previous patch: rings of neighbours added around the seeds"
    )


class LevelSetConfig(_Model):
    """The dissection law and its numerics (PHYSICS.md section 4)."""

    v0_m_per_s: Positive = V0_M_PER_S
    reinit_every: Annotated[int, Field(ge=1)] = REINIT_EVERY
    cfl: Annotated[float, Field(gt=0, le=1)] = CFL
    nonlocal_length_m: Annotated[float, Field(ge=0, le=0.01)] = Field(
        NONLOCAL_LENGTH_M,
        description="material length l (m) over which the strain energy that drives the cut is "
        "averaged (Gaussian, healthy tissue only); 0 is the local law",
    )
    removal: Literal["threshold", "fraction"] = Field(
        "threshold",
        description="how cut tissue enters conductivity, heat conduction, stiffness, pore "
        "pressure and the cut's driver: 'threshold' switches a tet to removed tissue once half "
        "its volume is cut; 'fraction' blends each tet's properties by the share still tissue, "
        "so the fields are continuous in the level set",
    )

    def law(self, kappa_j_per_m3: float) -> LevelSetLaw:
        """The law these settings give with the tissue's damage threshold kappa (J/m^3)."""
        return LevelSetLaw(
            v0_m_per_s=self.v0_m_per_s,
            kappa_j_per_m3=kappa_j_per_m3,
            cfl=self.cfl,
            reinit_every=self.reinit_every,
            nonlocal_length_m=self.nonlocal_length_m,
        )


class AccuracyBudget(_Model):
    """The largest error a user accepts; the engine picks the cheapest measured variant meeting it."""

    max_strain_energy_error: Annotated[float, Field(gt=0, le=1)] = Field(
        description="max relative strain-energy error over a run (the paper's metric), e.g. 0.02"
    )


class Scene(_Model):
    """Everything a simulation needs. Lengths in m, times in s."""

    schema_version: Literal[1] = SCHEMA_VERSION
    name: str = "custom"
    description: str = ""
    block_m: tuple[Positive, Positive, Positive] = (0.2, 0.1, 0.1)
    grid: tuple[int, int, int] = Field(
        (33, 33, 65), description="nodes (nz, ny, nx) of the uniform grid; unused with resolution"
    )
    resolution: Resolution | None = Field(
        None,
        description="a graded grid, fine under the electrodes; None: the uniform grid",
        # left out of dumps when absent: uniform scenes' run files stay byte-identical
        exclude_if=lambda v: v is None,
    )
    material: Tissue = Tissue()
    electrodes: list[Electrode] = Field(default_factory=lambda: [Electrode()])
    dt_s: Annotated[float, Field(gt=0, le=10.0)] = 0.03
    steps: Annotated[int, Field(ge=0)] = 100
    effects: list[Effect] = Field(default_factory=lambda: list(DEFAULT_EFFECTS))
    solver: SolverConfig = SolverConfig()
    mechanics: MechanicsConfig = MechanicsConfig()
    level_set: LevelSetConfig = LevelSetConfig()
    accuracy_budget: AccuracyBudget | None = None

    @field_validator("grid")
    @classmethod
    def _grid(cls, v: tuple[int, int, int]) -> tuple[int, int, int]:
        if any(n < 3 for n in v):
            raise ValueError(f"every node count must be >= 3, got {v}")
        return v

    @model_validator(mode="after")
    def _consistent(self) -> Scene:
        lx, ly, _ = self.block_m
        for i, el in enumerate(self.electrodes):
            for x, y in [el.position_m]:  # a path may leave the block: contact then ends
                if not (
                    -el.radius_m <= x <= lx + el.radius_m and -el.radius_m <= y <= ly + el.radius_m
                ):
                    raise ValueError(
                        f"electrodes.{i}: point ({x}, {y}) m lies off the top surface "
                        f"[0, {lx}] x [0, {ly}] m"
                    )
        if "electric" in self.effects and not self.electrodes:
            raise ValueError("effects: 'electric' needs at least one electrode")
        if len({e.name for e in self.electrodes}) != len(self.electrodes):
            raise ValueError("electrodes: names must be unique")
        if self.resolution is not None:
            try:
                n = self.node_grid().n_nodes
            except MeshError as e:
                raise ValueError(f"resolution: {e}") from None
            if n > MAX_GRADED_NODES:
                raise ValueError(
                    f"resolution: the graded grid would have {n} nodes (at most "
                    f"{MAX_GRADED_NODES}): raise fine_m, fine_z_m, growth or max_cell_m"
                )
        return self

    def node_grid(self) -> Grid:
        """The grid the engine meshes: uniform ``grid`` over the block, or graded (resolution)."""
        if self.resolution is None:
            return Grid(self.grid, size_m=self.block_m)
        return graded_grid(self.resolution, self.block_m, self.electrodes)

    def working_region(self) -> Box | None:
        """The box ((x, y, z) low, high) in m where ``node_grid()`` is fine (the working box with
        its deep tier, if any); None on a uniform grid (equally fine everywhere)."""
        if self.resolution is None:
            return None
        return resolved_region(self.resolution, self.block_m, self.electrodes)

    def on_uniform_grid(self, shape: tuple[int, int, int]) -> Scene:
        """This scene on a uniform grid of ``shape`` nodes (nz, ny, nx): its resolution dropped."""
        data = self.model_dump()
        data["grid"], data["resolution"] = tuple(shape), None
        return type(self).model_validate(data)

    @property
    def node_shape(self) -> tuple[int, int, int]:
        """Nodes (nz, ny, nx) of ``node_grid()``."""
        if self.resolution is None:
            return self.grid
        return self.node_grid().shape

    @property
    def closed_effects(self) -> tuple[str, ...]:
        """The effects called for plus what they need, in run order."""
        return close_effects(self.effects)
