"""The effects of a step, one module each, in the order a step runs them.

Each effect is two plain functions over the context, the state and the step: ``skip`` says
whether and why it does not run this step (and what it still sets), ``run`` does its work; both
return an ``Outcome`` (the report, the fields it replaces) and change nothing themselves.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from diathermy.engine.context import EngineContext
from diathermy.engine.effects import dissection, electric, mechanics, thermal, tissue, vaporization
from diathermy.engine.state import SimulationState
from diathermy.engine.step import Outcome, Step

EffectFn = Callable[[EngineContext, SimulationState, Step], Outcome]
SkipFn = Callable[[EngineContext, SimulationState, Step], "Outcome | None"]


class Effect(NamedTuple):
    """An effect's skip test and its step."""

    skip: SkipFn
    run: EffectFn


EFFECTS: dict[str, Effect] = {
    "electric": Effect(electric.skip, electric.run),
    "thermal": Effect(thermal.skip, thermal.run),
    "vaporization": Effect(vaporization.skip, vaporization.run),
    "mechanics": Effect(mechanics.skip, mechanics.run),
    "dissection": Effect(dissection.skip, dissection.run),
    "desiccation": Effect(tissue.never_skipped, tissue.desiccation),
    "thermal_damage": Effect(tissue.never_skipped, tissue.thermal_damage),
}
