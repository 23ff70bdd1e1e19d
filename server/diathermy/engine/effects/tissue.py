"""The tissue-change effects without a solve of their own: desiccation (it acts through the
conductivity of the next electric solve) and Arrhenius thermal damage.

thermal_damage reads temperature (start and end of step) and writes thermal_damage.
"""

from __future__ import annotations

from diathermy.engine.context import EngineContext
from diathermy.engine.report import EffectReport
from diathermy.engine.state import SimulationState
from diathermy.engine.step import Outcome, Step
from diathermy.physics.tissue_effects import arrhenius_damage_increment


def never_skipped(ctx: EngineContext, state: SimulationState, step: Step) -> Outcome | None:
    """These effects run every step."""
    return None


def desiccation(ctx: EngineContext, state: SimulationState, step: Step) -> Outcome:
    """Nothing to do in the step itself: the electric effect reads the conductivity law."""
    return Outcome(
        EffectReport(
            True,
            "applied in the conductivity of the next electric solve",
            extra={"mode": "local", "why": "no work of its own"},
        )
    )


def thermal_damage(ctx: EngineContext, state: SimulationState, step: Step) -> Outcome:
    """Omega += the Arrhenius integral over the step (trapezoid in T between start and end)."""
    omega = state["thermal_damage"] + arrhenius_damage_increment(
        step.T_old, state["temperature"], step.dt, ctx.damage_law
    )
    report = EffectReport(True, extra={"mode": "full", "why": "Arrhenius increment at every node"})
    return Outcome(report, fields={"thermal_damage": omega})
