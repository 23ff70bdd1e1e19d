"""Dissection effect: the level-set cut moves where the strain energy passes kappa.

Reads strain_energy, removed, level_set; writes level_set and removed (cut or loose); remembers
the topology and the re-initialisation counter.
"""

from __future__ import annotations

import numpy as np

from diathermy.engine.context import EngineContext
from diathermy.engine.removal import tissue_share
from diathermy.engine.report import EffectReport
from diathermy.engine.state import SimulationState
from diathermy.engine.step import Outcome, Step, skipped
from diathermy.physics.dissection import cut_moves, dissection_step


def skip(ctx: EngineContext, state: SimulationState, step: Step) -> Outcome | None:
    """Skipped when W stays below kappa everywhere: the front cannot move."""
    if cut_moves(state["strain_energy"], ctx.tissue.damage_kappa_j_per_m3):
        return None
    return skipped("strain energy below kappa everywhere: the cut does not move")


def run(ctx: EngineContext, state: SimulationState, step: Step) -> Outcome:
    """One front advance, re-initialisation on schedule, the new topology."""
    res = dissection_step(
        state["level_set"],
        state["strain_energy"],
        state["removed"],
        mesh=ctx.disc.mesh,
        grid=ctx.disc.grid,
        volumes=ctx.disc.geom.volumes,
        incidence=ctx.incidence,
        law=ctx.scene.level_set.law(ctx.tissue.damage_kappa_j_per_m3),
        dt=step.dt,
        steps_since_reinit=state.memory.steps_since_reinit,
        previous=state.memory.topology,
        tissue_share=tissue_share(ctx, state),
    )
    changed = int(np.count_nonzero(res.removed != state["removed"]))
    return Outcome(
        EffectReport(
            True,
            iterations=res.n_substeps,
            extra={
                "active_nodes": res.n_active,
                "reinitialized": res.reinitialized,
                "tets_changed": changed,
                "loose_tets": int(res.topology.loose.sum()),
                "mode": "full",
                "why": f"front advance on the grid ({res.n_active} nodes moving), topology of "
                "every tet",
            },
        ),
        fields={"level_set": res.level_set, "removed": res.removed},
        memory={"topology": res.topology, "steps_since_reinit": res.steps_since_reinit},
    )
