"""One step as the effects see it: its inputs, what effects hand each other within it (named
fields, nothing hidden), and what an effect returns (its report, the fields it updates)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from diathermy.engine.electrodes import ElectrodePose
from diathermy.engine.report import EffectReport
from diathermy.physics.contact_load import ContactWeights
from diathermy.physics.driven_potential import ElectrodeDrive
from diathermy.physics.heat_operator import HeatEnergy


@dataclass(frozen=True)
class MonolithicRequest:
    """An electric solve the electric effect hands to the thermal one (monolithic coupling):
    the conductivity per tet (S/m), the contact and the drive."""

    sigma: np.ndarray
    contact: ContactWeights
    drive: ElectrodeDrive


@dataclass
class Step:
    """The inputs of one step and the data its effects pass on, in effect order.

    dt: step length in s; poses: every electrode at the step's midpoint; T_old: temperature (K)
    at the start of the step. rho_c: the volumetric heat capacity (J/(m^3 K)) the thermal step
    used, which vaporization's energy balance must reuse. monolithic: the electric solve
    deferred to the thermal step. delivered_power_w: the power the electric solve delivered.
    joule_load_w: the nodal load (n_nodes,) in W of this step's Joule heat, where the electric
    effect has it (scaled from the reused unit field); None: the thermal step sums it.
    """

    dt: float
    poses: list[ElectrodePose]
    T_old: np.ndarray
    rho_c: np.ndarray | None = None
    monolithic: MonolithicRequest | None = None
    delivered_power_w: float = 0.0
    joule_load_w: np.ndarray | None = None


@dataclass
class Outcome:
    """What one effect did: its report, the state fields it replaces, its entries in the energy
    ledger, the named memory (``EffectMemory``) and step fields (``Step``) it sets."""

    report: EffectReport
    fields: dict[str, np.ndarray] = field(default_factory=dict)
    heat: HeatEnergy | None = None
    latent_j: float | None = None
    memory: dict[str, Any] = field(default_factory=dict)
    handoff: dict[str, Any] = field(default_factory=dict)


def skipped(reason: str, **fields: np.ndarray) -> Outcome:
    """The outcome of an effect that does not run this step (and the fields it still sets)."""
    return Outcome(EffectReport(False, reason), fields=dict(fields))
