"""What one step did: which effects ran or were skipped and why, their cost, and key figures."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any


@dataclass
class EffectReport:
    """One effect in one step: ran or skipped (with the reason), wall time in s, solver stats."""

    ran: bool
    reason: str = ""
    wall_s: float = 0.0
    iterations: int = 0
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass
class StepReport:
    """The report of one step; ``to_dict`` gives the JSON record stored in run files.

    ``max_displacement_m``: the largest |u| (m) on the tissue's nodes (``topology.tissue_nodes``;
    the crater's near-void nodes left out once something is cut).
    ``beyond_fine_region_m``: how far the cut, the vapor and the lesion reach beyond a graded
    grid's working region, in m (0: inside; empty on a uniform grid; ``engine.fine_region``).
    ``left_out_effects``: the effects the scene leaves out that this step's state says would act,
    each with why (``engine.left_out``; empty when the scene's effects suffice)."""

    step: int
    time_s: float
    effects: dict[str, EffectReport] = field(default_factory=dict)
    wall_s: float = 0.0
    delivered_power_w: float = 0.0
    max_temperature_k: float = 0.0
    max_pressure_pa: float = 0.0
    max_displacement_m: float = 0.0
    max_strain_energy_j_per_m3: float = 0.0
    cut_volume_m3: float = 0.0
    crater_depth_m: float = 0.0
    beyond_fine_region_m: dict[str, float] = field(default_factory=dict)
    left_out_effects: dict[str, str] = field(default_factory=dict)
    energy: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def ran(self, effect: str) -> bool:
        rep = self.effects.get(effect)
        return bool(rep and rep.ran)
