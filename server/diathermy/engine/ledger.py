"""The running energy totals of a simulation in J: what the Joule source put in, what the surface
lost by convection, and what the tissue stores as sensible and as latent heat."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diathermy.physics.heat_operator import HeatEnergy


@dataclass
class EnergyLedger:
    """Energy totals since t = 0 in J; ``imbalance`` is zero up to the solver residuals."""

    joule_in: float = 0.0
    convective_out: float = 0.0
    sensible_stored: float = 0.0
    latent_stored: float = 0.0

    @property
    def imbalance(self) -> float:
        """joule_in - convective_out - sensible_stored - latent_stored, in J."""
        return self.joule_in - self.convective_out - self.sensible_stored - self.latent_stored

    def add_heat(self, energy: HeatEnergy) -> None:
        """Book one heat step: the Joule input, the convective loss and the sensible change."""
        self.joule_in += energy.joule_j
        self.convective_out += energy.convective_loss_j
        self.sensible_stored += energy.stored_j

    def move_to_latent(self, joules: float) -> None:
        """Book heat that vaporization moved from the sensible to the latent store."""
        self.sensible_stored -= joules
        self.latent_stored += joules

    def totals(self) -> dict[str, float]:
        """The four totals by name (the checkpoint's JSON form)."""
        return {
            "joule_in": self.joule_in,
            "convective_out": self.convective_out,
            "sensible_stored": self.sensible_stored,
            "latent_stored": self.latent_stored,
        }

    def report(self) -> dict[str, float]:
        """The totals and the imbalance, as a step report records them."""
        return {**self.totals(), "imbalance": self.imbalance}

    @classmethod
    def from_totals(cls, totals: dict[str, float]) -> EnergyLedger:
        """The ledger of ``totals`` (``totals()``'s form); unknown or missing names raise."""
        return cls(**{k: float(v) for k, v in totals.items()})


def latent_heat_moved_j(
    node_volumes_m3: np.ndarray, x_old: np.ndarray, x_new: np.ndarray, latent_per_m3: float
) -> float:
    """Heat in J moved into the latent store when the vapor fraction goes from x_old to x_new,
    with ``latent_per_m3`` the latent heat of all the water per volume (J/m^3, ``m_w h_fg``)."""
    return float(np.dot(node_volumes_m3, latent_per_m3 * (x_new - x_old)))
