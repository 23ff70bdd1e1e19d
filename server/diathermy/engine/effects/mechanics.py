"""Mechanics effect: the displacement under the pore pressure, and its strain energy density.

Reads pressure, removed, level_set, displacement (warm start); writes displacement and
strain_energy; remembers the (pressure, removed) it solved for, so an unchanged load is reused.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from diathermy.engine.context import EngineContext
from diathermy.engine.removal import tissue_share
from diathermy.engine.report import EffectReport
from diathermy.engine.state import SimulationState
from diathermy.engine.step import Outcome, Step
from diathermy.physics.mechanics_backend import solve_with_cut


def load_key(state: SimulationState, share: np.ndarray | None) -> tuple[bytes, bytes, bytes]:
    """What the displacement depends on: the pressure, the removed mask and the tissue shares
    (``removal.tissue_share``; None under 'threshold' removal), as bytes."""
    return (
        state["pressure"].tobytes(),
        state["removed"].tobytes(),
        b"" if share is None else share.tobytes(),
    )


def skip(ctx: EngineContext, state: SimulationState, step: Step) -> Outcome | None:
    """Skipped with u = 0 when p = p0 everywhere, and reused when p and the cut are unchanged."""
    if not np.any(state["pressure"] != ctx.tissue.p_atm_pa):
        return Outcome(
            EffectReport(False, "pressure is p0 everywhere: u = 0, W = 0"),
            fields={
                "displacement": np.zeros((ctx.disc.n_nodes, 3)),
                "strain_energy": np.zeros(ctx.disc.n_tets),
            },
            memory={"mechanics_key": None},
        )
    if load_key(state, tissue_share(ctx, state)) == state.memory.mechanics_key:
        return Outcome(EffectReport(False, "pressure and topology unchanged: displacement reused"))
    return None


def mode_of(backend: str, extra: dict[str, Any]) -> dict[str, str]:
    """Local or full, why, and which predictor, for a backend that does not say so itself."""
    if backend == "fem":
        return {"mode": "full", "why": "full solve every step (mechanics.predictor 'none' or "
                "solver.incremental false)", "predictor": "none"}  # fmt: skip
    if extra.get("corrected"):
        return {
            "mode": "full",
            "why": "the surrogate's residual exceeded the guard: CG on the block",
            "predictor": backend,
        }
    return {
        "mode": "local",
        "why": f"{backend} prediction, patch of {extra.get('patch_nodes', 0)} nodes",
        "predictor": backend,
    }


def run(ctx: EngineContext, state: SimulationState, step: Step) -> Outcome:
    """Solve the displacement with the scene's backend (removed tissue as ersatz material)."""
    backend = ctx.mechanics
    share = tissue_share(ctx, state)
    out, W = solve_with_cut(
        backend,
        pressure_pa=state["pressure"],
        level_set_m=state["level_set"],
        removed=state["removed"],
        tissue_share=share,
        warm_start=state["displacement"],
        tissue=ctx.tissue,
        grads=ctx.disc.geom.grads,
        tets=ctx.disc.mesh.tets,
        previous_W=state["strain_energy"],
        grid=ctx.disc.mesh.grid,
    )
    return Outcome(
        EffectReport(
            True,
            iterations=out.iterations,
            extra={
                "backend": backend.name,
                "rebuilt": out.rebuilt,
                "residual": out.residual,
                **mode_of(backend.name, out.extra),
                **out.extra,
            },
        ),
        fields={"displacement": out.u, "strain_energy": W},
        memory={"mechanics_key": load_key(state, share)},
    )
