"""The simulation a session holds: a scene, the state of every field, and a step that runs
exactly the effects the scene calls for (``pipeline``; one module per effect in ``effects/``).

Policy is the caller's: a scene's accuracy budget is resolved before it gets here
(``report.budget.resolve_accuracy_budget``), and surrogate model names are looked up by the
``ModelResolver`` the caller hands in (the CLI and the service pass their model registry).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np

from diathermy.engine import checkpoint as persistence
from diathermy.engine import fields
from diathermy.engine.backends import ModelResolver, make_backend
from diathermy.engine.changes import ChangeSet
from diathermy.engine.context import EngineContext
from diathermy.engine.discretization import Discretization
from diathermy.engine.electrodes import ElectrodeOverride, electrode_pose, override_electrode
from diathermy.engine.pipeline import StepResult, run_step
from diathermy.engine.report import StepReport
from diathermy.engine.state import SimulationState, initial_state
from diathermy.errors import SceneError
from diathermy.mesh import Grid
from diathermy.physics.cut_surface import CutSurface, cut_surface, write_cut_surface
from diathermy.physics.driven_potential import DrivenPotential
from diathermy.physics.levelset import initial_level_set
from diathermy.physics.materials import Tissue
from diathermy.physics.mechanics_backend import MechanicsBackend
from diathermy.physics.topology import Topology
from diathermy.scene import Scene


class Simulation:
    """State and stepping of one scene. Not thread-safe: one caller steps it at a time."""

    def __init__(
        self,
        scene: Scene,
        *,
        mechanics_backend: MechanicsBackend | None = None,
        models: ModelResolver | None = None,
    ) -> None:
        if scene.accuracy_budget is not None:
            raise SceneError(
                "accuracy_budget: the caller resolves it to a mechanics variant before building "
                "the simulation (report.budget.resolve_accuracy_budget)"
            )
        self.models = models
        self.ctx = EngineContext(scene, self._build_mechanics)
        self.scene = scene
        disc = self.ctx.disc
        self.state: SimulationState = initial_state(
            disc.n_nodes, disc.n_tets, disc.mesh.points[:, 2], self.ctx.top_z, scene.material
        )
        self.state["level_set"] = initial_level_set(disc.grid).ravel().copy()
        self.calls: Counter[str] = Counter()
        self.last_report: StepReport | None = None
        self._last_result: StepResult | None = None
        if mechanics_backend is not None:
            self.ctx.mechanics = mechanics_backend
        elif (
            scene.mechanics.backend != "fem" or scene.mechanics.predictor == "auto"
        ) and self.ctx.has("mechanics"):
            self.ctx.mechanics  # noqa: B018  a missing or wrong model fails here, not later

    def _build_mechanics(self, ctx: EngineContext) -> MechanicsBackend:
        return make_backend(ctx, models=self.models, position=self._active_position)

    def _active_position(self) -> tuple[float, float] | None:
        """The coming step's position of the first active electrode (PGD's online parameter)."""
        t_mid = self.state.time_s + 0.5 * self.scene.dt_s  # the step's pose time
        for el in self.scene.electrodes:
            pose = electrode_pose(el, t_mid, self.state.overrides.get(el.name))
            if pose.active:
                return pose.position_m
        return None

    # ------------------------------------------------------------------ what it holds
    @property
    def disc(self) -> Discretization:
        return self.ctx.disc

    @property
    def tissue(self) -> Tissue:
        return self.ctx.tissue

    @property
    def effects(self) -> tuple[str, ...]:
        return self.ctx.effects

    @property
    def grid(self) -> Grid:
        return self.ctx.disc.grid

    @property
    def potential(self) -> DrivenPotential:
        return self.ctx.potential

    @property
    def step_index(self) -> int:
        return self.state.step

    @property
    def time_s(self) -> float:
        return self.state.time_s

    @property
    def topology(self) -> Topology | None:
        """The cut's topology after the last dissection step."""
        return self.state.memory.topology

    @topology.setter
    def topology(self, value: Topology | None) -> None:
        self.state.memory.topology = value

    @property
    def last_changes(self) -> ChangeSet | None:
        """What the last step changed (None before the first step); computed on first use."""
        return None if self._last_result is None else self._last_result.changes

    @property
    def last_effect_changes(self) -> dict[str, ChangeSet]:
        """What each effect of the last step changed."""
        return {} if self._last_result is None else self._last_result.by_effect

    @property
    def mechanics(self) -> MechanicsBackend:
        """The mechanics backend (FEM unless the scene or caller chose a surrogate)."""
        return self.ctx.mechanics

    @mechanics.setter
    def mechanics(self, backend: MechanicsBackend) -> None:
        self.ctx.mechanics = backend

    # ------------------------------------------------------------------ fields
    def dof_counts(self) -> dict[str, int]:
        """Unknowns per field of this scene's effects."""
        return fields.dof_counts(self.disc, self.effects)

    def field_names(self) -> list[str]:
        return list(fields.FIELD_NAMES)

    def field(self, name: str) -> np.ndarray:
        """A copy of one field: nodal grid-shaped (nz, ny, nx[, 3]) or per tet (n_tets,)."""
        return fields.field(self.disc, self.state, name)

    def nodal_fields(self) -> dict[str, np.ndarray]:
        """The fields of the scene's effects, grid-shaped, for run files."""
        return fields.nodal_fields(self.disc, self.state, self.effects)

    def cell_fields(self) -> dict[str, np.ndarray]:
        return fields.cell_fields(self.state, self.effects)

    def cut_surface(self) -> tuple[np.ndarray, np.ndarray]:
        """The phi = 0 surface: vertices (n, 3) in m and triangles (m, 3)."""
        surf: CutSurface = cut_surface(self.disc.to_grid(self.state["level_set"]), self.grid)
        return surf.vertices, surf.faces

    # ------------------------------------------------------------------ control and stepping
    def set_electrode(
        self,
        name: str,
        *,
        position_m: tuple[float, float] | None = None,
        power_w: float | None = None,
        current_density_a_per_m2: float | None = None,
        active: bool | None = None,
        max_voltage_v: float | None = None,
    ) -> None:
        """Change an electrode between steps (pose, drive, on/off, the generator's voltage
        limit: 0 lifts it); None keeps the current value."""
        self.state.overrides[name] = override_electrode(
            self.scene,
            name,
            self.state.overrides.get(name, ElectrodeOverride()),
            position_m=position_m,
            power_w=power_w,
            current_density_a_per_m2=current_density_a_per_m2,
            active=active,
            max_voltage_v=max_voltage_v,
        )

    def step(self) -> StepReport:
        """Advance one time step of the scene's dt; returns what ran, what it cost, key figures.

        What the step changed is in ``last_changes`` (per effect: ``last_effect_changes``)."""
        result = run_step(self.ctx, self.state, self.calls)
        self.last_report = result.report
        self._last_result = result
        return result.report

    def run(self, n: int, callback: Callable[[StepReport], None] | None = None) -> list[StepReport]:
        """Advance n steps; the callback sees each report."""
        reports = []
        for _ in range(n):
            rep = self.step()
            reports.append(rep)
            if callback is not None:
                callback(rep)
        return reports

    # ------------------------------------------------------------------ output and persistence
    def write_vtu(self, path: str | Path) -> Path:
        """The current state as a ParaView VTU file."""
        from diathermy.engine.vtu import write_vtu

        nodal = {
            n: v.reshape(self.disc.n_nodes, -1).squeeze() for n, v in self.nodal_fields().items()
        }
        cells = {k: v.astype(np.float64) for k, v in self.cell_fields().items()}
        return write_vtu(path, self.disc.mesh.points, self.disc.mesh.tets, nodal, cells)

    def write_cut_surface(self, path: str | Path) -> None:
        """The cut (phi = 0) as a triangle mesh file; the suffix picks the format (.vtu, .ply, .stl)."""
        write_cut_surface(path, cut_surface(self.disc.to_grid(self.state["level_set"]), self.grid))

    def solver_state(self) -> dict[str, np.ndarray]:
        """Solver data that decides the next iterates: the cached unit potential, warm starts."""
        return persistence.solver_state(self.ctx)

    def restore_solver_state(
        self, solver: dict[str, np.ndarray], *, steps_since_reinit: int, mechanics_current: bool
    ) -> None:
        """Put back what ``solver_state`` saved, so the next step repeats the original run."""
        persistence.restore_solver_state(
            self.ctx,
            self.state,
            solver,
            steps_since_reinit=steps_since_reinit,
            mechanics_current=mechanics_current,
        )

    def save_checkpoint(self, path: str | Path) -> Path:
        """The whole state in one HDF5 file (see ``engine.checkpoint``)."""
        return persistence.save_checkpoint(path, self.scene, self.state, self.solver_state())

    @classmethod
    def load_checkpoint(
        cls,
        path: str | Path,
        *,
        models: ModelResolver | None = None,
        scene: Callable[[Scene], Scene] | None = None,
    ) -> Simulation:
        """A simulation that continues a checkpoint exactly; bad files raise ``CheckpointError``.

        ``scene``: maps the saved scene to the one to continue under (other solver or mechanics
        settings on the same grid, e.g. to compare modes from one state); None keeps it."""
        saved = persistence.read_checkpoint(path)
        sim = cls(saved.scene if scene is None else scene(saved.scene), models=models)
        persistence.check_fields(path, sim.state.arrays, saved.arrays)
        st = sim.state
        st.step, st.time_s, st.arrays = saved.step, saved.time_s, saved.arrays
        st.energy, st.overrides = saved.energy, saved.overrides
        sim.restore_solver_state(
            saved.solver,
            steps_since_reinit=saved.steps_since_reinit,
            mechanics_current=saved.mechanics_current,
        )
        return sim
