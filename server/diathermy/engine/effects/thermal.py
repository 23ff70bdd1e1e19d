"""Thermal effect: one implicit heat step with the Joule source, convective cooling at the surface.

Reads temperature (start of step), vapor_fraction, pressure, removed, joule_heat; writes
temperature (and, coupled monolithically, potential and joule_heat); hands its rho c to
vaporization; books the heat in the energy ledger.
"""

from __future__ import annotations

import numpy as np

from diathermy.engine.context import EngineContext
from diathermy.engine.removal import tissue_share
from diathermy.engine.report import EffectReport
from diathermy.engine.state import SimulationState
from diathermy.engine.step import Outcome, Step, skipped
from diathermy.mesh.kuhn_fields import tet_mean
from diathermy.physics.materials import share_blend
from diathermy.physics.properties import effective_conductivity, volumetric_heat_capacity


def skip(ctx: EngineContext, state: SimulationState, step: Step) -> Outcome | None:
    """Skipped when nothing heats and the block is at ambient temperature."""
    if not state["joule_heat"].any() and np.all(step.T_old == ctx.heat.t_ambient_k):
        return skipped("no heat source and the block is at ambient temperature")
    return None


def heat_conductivity(ctx: EngineContext, state: SimulationState) -> np.ndarray:
    """k per tet in W/(m K): the vapor-liquid mixture's, vapor's in removed tets (blended by
    each tet's tissue share under ``level_set.removal`` 'fraction')."""
    t = ctx.tissue
    x = state["vapor_fraction"]
    if x.any():
        k = tet_mean(effective_conductivity(x, t), ctx.disc.grid)
    else:  # no vapor yet: the liquid-phase mixture everywhere
        k = np.full(ctx.disc.n_tets, float(effective_conductivity(0.0, t)))
    share = tissue_share(ctx, state)
    if share is not None:
        return share_blend(share, k, t.k_vapor_w_per_m_k)
    k[state["removed"]] = t.k_vapor_w_per_m_k
    return k


def run(ctx: EngineContext, state: SimulationState, step: Step) -> Outcome:
    """The heat step from the step's starting temperature (staggered, or monolithic with V)."""
    x = state["vapor_fraction"]
    rho_c = volumetric_heat_capacity(x, state["pressure"], step.T_old, ctx.tissue)
    k = heat_conductivity(ctx, state)
    if step.monolithic is not None:
        req = step.monolithic
        mono = ctx.coupled.monolithic_step(
            step.T_old,
            step.dt,
            sigma=req.sigma,
            contact=req.contact,
            drive=req.drive,
            rho_c=rho_c,
            k=k,
            rtol=ctx.scene.solver.thermal_rtol,
        )
        return Outcome(
            EffectReport(
                True,
                iterations=mono.heat.iterations,
                extra={
                    "coupling": "monolithic",
                    "picard_passes": mono.picard_passes,
                    "mode": "full",
                    "why": "monolithic coupling: potential and temperature of the whole block",
                },
            ),
            fields={"temperature": mono.T, "potential": mono.V, "joule_heat": mono.q},
            heat=mono.energy,
            handoff={"rho_c": rho_c, "monolithic": None, "delivered_power_w": mono.power_w},
        )
    res = ctx.heat.step(
        step.T_old,
        step.dt,
        rho_c=rho_c,
        k=k,
        q=state["joule_heat"],
        joule_load_w=step.joule_load_w,
    )
    return Outcome(
        EffectReport(
            True,
            iterations=res.stats.iterations,
            extra={
                "preconditioner": res.stats.preconditioner,
                "fallback_nodes": int(res.stats.fallback_nodes.size),
                "mode": "full",
                "why": f"implicit heat step of the whole block ({res.stats.preconditioner}-CG, "
                f"{res.stats.iterations} iterations: cheaper than any local scheme)",
            },
        ),
        fields={"temperature": res.T},
        heat=res.energy,
        handoff={"rho_c": rho_c},
    )
