"""Electric effect: the potential of the active electrodes' contact and its Joule heat.

Reads temperature, vapor_fraction (desiccation), removed, level_set (contact height); writes
potential and joule_heat, or hands the solve to the thermal effect (monolithic coupling).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from diathermy.engine.contact import combined, contact_key, drives_current
from diathermy.engine.context import EngineContext
from diathermy.engine.electrodes import ElectrodePose
from diathermy.engine.removal import tissue_share
from diathermy.engine.report import EffectReport
from diathermy.engine.state import ContactKey, SimulationState
from diathermy.engine.step import MonolithicRequest, Outcome, Step
from diathermy.mesh.kuhn_fields import tet_mean
from diathermy.physics.contact_load import ContactWeights
from diathermy.physics.driven_potential import voltage_limited
from diathermy.physics.electric import joule_heat
from diathermy.physics.materials import share_blend
from diathermy.physics.tissue_effects import electrical_conductivity

NO_CONTACT = (
    "no active electrode in contact with the tissue (off the block, or cut through "
    "to the return electrode)"
)


def conductivity(ctx: EngineContext, state: SimulationState) -> np.ndarray:
    """sigma per tet in S/m: the tissue's (or desiccation's law of T and x), removed tets ~0
    (blended by each tet's tissue share under ``level_set.removal`` 'fraction')."""
    t = ctx.tissue
    if ctx.has("desiccation"):
        sigma_n = electrical_conductivity(
            state["temperature"], state["vapor_fraction"], t, ctx.conductivity_law
        )
        sigma = tet_mean(sigma_n, ctx.disc.grid)
    else:
        sigma = np.full(ctx.disc.n_tets, t.sigma_s_per_m)
    share = tissue_share(ctx, state)
    if share is not None:
        return share_blend(share, sigma, t.sigma_removed_s_per_m)
    sigma[state["removed"]] = t.sigma_removed_s_per_m
    return sigma


def contacts(
    ctx: EngineContext, state: SimulationState, step: Step
) -> list[tuple[ElectrodePose, ContactKey, ContactWeights]]:
    """The electrodes that drive current this step and touch the tissue, with their contact
    disk (key and weights), in scene order."""
    cut = ctx.has("dissection") and bool(state["removed"].any())
    out = []
    for pose in step.poses:
        if not drives_current(pose):
            continue
        key = contact_key(ctx.disc, state, pose, top_z=ctx.top_z, cut=cut)
        c = None if key is None else ctx.contacts.get(ctx.disc, key)
        if c is not None and key is not None:
            out.append((pose, key, c))
    return out


def skip(ctx: EngineContext, state: SimulationState, step: Step) -> Outcome | None:
    """Skipped (V = 0, q = 0) when no active electrode touches the tissue."""
    if contacts(ctx, state, step):
        return None
    return Outcome(
        EffectReport(False, NO_CONTACT),
        fields={"potential": np.zeros(ctx.disc.n_nodes), "joule_heat": np.zeros(ctx.disc.n_tets)},
        memory={"contacts": ()},
    )


def run(ctx: EngineContext, state: SimulationState, step: Step) -> Outcome:
    """Solve the potential (or reuse the unit-current one scaled to the drive)."""
    found = contacts(ctx, state, step)
    contact, drive = combined([(pose, c) for pose, _, c in found])
    keys = tuple(k for _, k, _ in found)
    sigma = conductivity(ctx, state)
    if ctx.scene.solver.coupling == "monolithic" and ctx.has("thermal"):
        return Outcome(
            EffectReport(
                True,
                "solved with the temperature by block-preconditioned GMRES (monolithic)",
                extra={"mode": "full", "why": "monolithic coupling with the heat step"},
            ),
            memory={"contacts": keys},
            handoff={"monolithic": MonolithicRequest(sigma, contact, drive)},
        )
    sol = ctx.potential.solve(sigma, contact, drive)
    # q is quadratic in the current: the unit field's Joule heat (and, for the heat step, its
    # nodal load) is computed once per unit field and scaled by I^2 while the field is reused
    i2 = sol.current_a**2
    q1 = ctx.potential.per_unit("joule_heat", lambda V1: joule_heat(ctx.disc.grid, sigma, V1))
    fields = {"potential": sol.V, "joule_heat": i2 * q1}
    handoff: dict[str, Any] = {"delivered_power_w": sol.power_w}
    # the electrode's voltage, and whether the generator's limit held it there
    volts = {
        "voltage_v": sol.current_a * sol.resistance_ohm,
        "voltage_limited": voltage_limited(drive, sol.current_a, sol.resistance_ohm),
    }
    if ctx.has("thermal"):
        load1 = ctx.potential.per_unit("joule_load", lambda _: ctx.heat.hmesh.joule_load(q1))
        handoff["joule_load_w"] = i2 * load1
    if sol.stats.cached:
        report = EffectReport(
            False,
            "conductivity and contact unchanged: potential reused (scaled to the drive)",
            extra={"current_a": sol.current_a, **volts},
        )
    else:
        st = sol.stats
        extra: dict[str, Any] = {
            "current_a": sol.current_a,
            **volts,
            "residual": st.residual,
            "reassembled": st.reassembled,
            "setup_s": st.setup_s,
        }
        if st.energy_estimate is not None:
            tol = ctx.scene.solver.electric_energy_tolerance
            window = (
                f"corrected exactly on the {st.window_nodes} nodes around its residual, then "
                if st.window_nodes
                else ""
            )
            extra.update(
                energy_estimate=st.energy_estimate,
                energy_tolerance=tol,
                window_nodes=st.window_nodes,
                mode="local",
                why=f"the last potential {window}{st.iterations} CG iterations with the kept "
                f"hierarchy: energy-error estimate {st.energy_estimate:.1e} <= {tol:.0e}",
            )
        else:
            extra.update(
                mode="full",
                why="conductivity or contact changed: CG over the block from the last "
                f"potential, AMG {'rebuilt' if st.setup_s > 0 else 'kept'}",
            )
        report = EffectReport(True, iterations=st.iterations, extra=extra)
    return Outcome(report, fields=fields, memory={"contacts": keys}, handoff=handoff)
