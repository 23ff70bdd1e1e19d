"""The step: a short loop over the scene's effects, each skipped or run, its outcome applied.

One step (dt from the scene) runs, in this order and only where the scene calls for them:
electric -> thermal -> vaporization (EOS) -> mechanics -> dissection -> desiccation -> thermal
damage. Besides the effects a scene leaves out, a step skips work that provably changes nothing
and says why in its report: no active electrode (no electric solve), the potential of an
unchanged conductivity and contact (reused), no node above saturation (p = p0, no EOS),
p = p0 everywhere (u = 0, no mechanics solve), W below kappa everywhere (no level-set update).
"""

from __future__ import annotations

import dataclasses
import time
from collections import Counter
from dataclasses import dataclass

import numpy as np

from diathermy.engine.changes import ChangeSet, PendingChanges
from diathermy.engine.context import EngineContext
from diathermy.engine.effects import EFFECTS
from diathermy.engine.electrodes import electrode_pose
from diathermy.engine.fine_region import beyond_fine_region
from diathermy.engine.left_out import left_out_acting
from diathermy.engine.report import StepReport
from diathermy.engine.state import SimulationState
from diathermy.engine.step import Outcome, Step
from diathermy.physics.topology import tissue_nodes


@dataclass(frozen=True)
class StepResult:
    """A step's report, and what it changed in all and per effect (computed on first use)."""

    report: StepReport
    pending: PendingChanges
    pending_by_effect: dict[str, PendingChanges]

    @property
    def changes(self) -> ChangeSet:
        """What the step changed."""
        return self.pending.resolve()

    @property
    def by_effect(self) -> dict[str, ChangeSet]:
        """What each effect changed."""
        return {name: p.resolve() for name, p in self.pending_by_effect.items()}


def begin_step(ctx: EngineContext, state: SimulationState) -> Step:
    """The inputs of the next step: dt, every electrode's pose at its midpoint, T at its start."""
    dt = ctx.scene.dt_s
    t_mid = state.time_s + 0.5 * dt
    poses = [electrode_pose(el, t_mid, state.overrides.get(el.name)) for el in ctx.scene.electrodes]
    return Step(dt=dt, poses=poses, T_old=state["temperature"].copy())


def apply_outcome(state: SimulationState, step: Step, outcome: Outcome) -> PendingChanges:
    """Put an effect's outcome into the state and the step; returns what it changed."""
    moved = "contacts" in outcome.memory and outcome.memory["contacts"] != state.memory.contacts
    before = {name: state.arrays[name] for name in outcome.fields}
    changes = PendingChanges(before, dict(outcome.fields), contact_moved=moved)
    state.arrays.update(outcome.fields)
    if outcome.heat is not None:
        state.energy.add_heat(outcome.heat)
    if outcome.latent_j is not None:
        state.energy.move_to_latent(outcome.latent_j)
    if outcome.memory:
        state.memory = dataclasses.replace(state.memory, **outcome.memory)
    for name, value in outcome.handoff.items():
        if name not in Step.__dataclass_fields__:
            raise AttributeError(f"an effect handed on {name!r}, which is no field of Step")
        setattr(step, name, value)
    return changes


def run_step(ctx: EngineContext, state: SimulationState, calls: Counter[str]) -> StepResult:
    """Advance ``state`` one step of the scene's effects; ``calls`` counts each effect's runs."""
    t_start = time.perf_counter()
    step = begin_step(ctx, state)
    rep = StepReport(step=state.step + 1, time_s=state.time_s + step.dt)
    start, contacts_before = dict(state.arrays), state.memory.contacts
    by_effect: dict[str, PendingChanges] = {}
    for name in ctx.effects:
        effect = EFFECTS[name]
        t0 = time.perf_counter()
        outcome = effect.skip(ctx, state, step)
        if outcome is None:
            calls[name] += 1
            outcome = effect.run(ctx, state, step)
        by_effect[name] = apply_outcome(state, step, outcome)
        outcome.report.wall_s = time.perf_counter() - t0
        rep.effects[name] = outcome.report
    state.step += 1
    state.time_s = state.step * step.dt  # no drift from summing dt
    rep.delivered_power_w = step.delivered_power_w
    finish_report(rep, state, ctx)
    replaced = {k: v for k, v in state.arrays.items() if v is not start[k]}
    changes = PendingChanges(
        {k: start[k] for k in replaced},
        replaced,
        contact_moved=state.memory.contacts != contacts_before,
    )
    rep.wall_s = time.perf_counter() - t_start
    return StepResult(rep, changes, by_effect)


def finish_report(rep: StepReport, state: SimulationState, ctx: EngineContext) -> None:
    """The key figures of the state after the step, and the energy ledger."""
    rep.max_temperature_k = float(state["temperature"].max())
    rep.max_pressure_pa = float(state["pressure"].max())
    u = np.linalg.norm(state["displacement"], axis=1)
    if state["removed"].any():  # the tissue's, not the crater's near-void nodes
        u = u[tissue_nodes(state["removed"], ctx.disc.mesh.tets, ctx.disc.n_nodes, ctx.incidence)]
    rep.max_displacement_m = float(u.max(initial=0.0))
    rep.max_strain_energy_j_per_m3 = float(state["strain_energy"].max())
    topology = state.memory.topology
    if topology is not None:
        rep.cut_volume_m3 = topology.cut_volume_m3
        rep.crater_depth_m = topology.crater_depth_m
    rep.beyond_fine_region_m = beyond_fine_region(
        ctx.disc.grid,
        ctx.working_region,
        state["level_set"],
        state["vapor_fraction"],
        state["thermal_damage"],
    )
    rep.left_out_effects = left_out_acting(
        ctx.effects,
        ctx.tissue,
        max_temperature_k=rep.max_temperature_k,
        max_pressure_pa=rep.max_pressure_pa,
        max_strain_energy_j_per_m3=rep.max_strain_energy_j_per_m3,
        delivered_power_w=rep.delivered_power_w,
    )
    rep.energy = state.energy.report()
