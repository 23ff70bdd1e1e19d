"""Vaporization effect (EOS): the local energy balance splits latent heat off the heat step.

Reads temperature (the heat step's trial T*), vapor_fraction, pressure and the step's rho c;
writes temperature, vapor_fraction, pressure; books the latent heat in the energy ledger.
"""

from __future__ import annotations

import numpy as np

from diathermy.engine.context import EngineContext
from diathermy.engine.ledger import latent_heat_moved_j
from diathermy.engine.report import EffectReport
from diathermy.engine.state import SimulationState
from diathermy.engine.step import Outcome, Step, skipped
from diathermy.physics.eos import latent_heat_per_volume, local_energy_balance
from diathermy.physics.properties import volumetric_heat_capacity


def skip(ctx: EngineContext, state: SimulationState, step: Step) -> Outcome | None:
    """Skipped (p = p0) when no node is above saturation and there is no vapor."""
    t = ctx.tissue
    if state["temperature"].max() > t.t_boil_k or state["vapor_fraction"].any():
        return None
    return skipped(
        "no node above saturation: p = p0, no vapor",
        pressure=np.full(ctx.disc.n_nodes, t.p_atm_pa),
    )


def run(ctx: EngineContext, state: SimulationState, step: Step) -> Outcome:
    """T, x, p at the equilibrium of the energy the heat step put in."""
    t = ctx.tissue
    T_star, x_old = state["temperature"], state["vapor_fraction"]
    rho_c = step.rho_c
    if rho_c is None:  # no heat step this step: the capacity of the old state
        rho_c = volumetric_heat_capacity(x_old, state["pressure"], step.T_old, t)
    eos = local_energy_balance(T_star, x_old, rho_c, t)
    # the latent heat moved out of the sensible store this step (exact split, see eos)
    latent = latent_heat_moved_j(ctx.disc.node_volumes_m3, x_old, eos.x, latent_heat_per_volume(t))
    return Outcome(
        EffectReport(
            True,
            iterations=eos.iterations,
            extra={
                "vapor_nodes": int(np.count_nonzero(eos.x)),
                "mode": "full",
                "why": "pointwise EOS at every node (vectorised, no coupled solve)",
            },
        ),
        fields={"temperature": eos.T, "vapor_fraction": eos.x, "pressure": eos.p},
        latent_j=latent,
    )
