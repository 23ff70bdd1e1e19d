"""The electrode's drive and the potential it sets (PHYSICS.md section 2).

V is linear in the injected current I and P = I^2 R, so one solve at unit current per
(conductivity, contact) serves both drives exactly: a constant current density j injects
I = j * area, a constant power P injects I = sqrt(P / R). R is the unit field's dissipation
int sigma |grad V1|^2 (the contact's int j1 V1 for an exact solve; the Joule heat itself for a
guarded one).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from diathermy.errors import SceneError, SolverDivergedError
from diathermy.physics.contact_load import ContactWeights, same_contact
from diathermy.physics.electric import PotentialSolver, PotentialStats


@dataclass(frozen=True)
class ElectrodeDrive:
    """How the generator drives the electrode: a fixed current density or a fixed power."""

    mode: Literal["current_density", "power"] = "current_density"
    current_density_a_per_m2: float = 5.72e4
    power_w: float = 50.0
    max_voltage_v: float | None = None
    """The generator's output limit in V (rms): where the set drive would need more, the
    electrode is held at this voltage and delivers V^2 / R (None: no limit)."""

    def __post_init__(self) -> None:
        if self.mode not in ("current_density", "power"):
            raise SceneError(f"electrode drive mode must be current_density or power: {self.mode}")
        if not self.current_density_a_per_m2 >= 0 or not self.power_w >= 0:
            raise SceneError("electrode current density and power must be non-negative")
        v = self.max_voltage_v
        if v is not None and not (np.isfinite(v) and v > 0):
            raise SceneError(f"electrode max_voltage_v must be a positive number of volts, got {v}")


@dataclass(frozen=True)
class PotentialSolution:
    """The driven potential: V (n_nodes,) in V, nodal current load (n_nodes,) in A, I, P, and
    the resistance R in ohm between the electrodes (the electrode's voltage is I R)."""

    V: np.ndarray
    load: np.ndarray
    current_a: float
    power_w: float
    stats: PotentialStats
    resistance_ohm: float = 0.0


class DrivenPotential:
    """The electrode's potential for any drive, from one solve at unit current per (sigma, contact).

    V is linear in the injected current I and P = I^2 R, so the unit-current field V1 (with
    R = int j1 V1) serves both drives exactly: constant j uses I = j * area, constant power
    I = sqrt(P / R). Re-solves only when the conductivity or the contact changes.
    """

    def __init__(self, solver: PotentialSolver) -> None:
        self.solver = solver
        self._contact: ContactWeights | None = None
        self._unit: tuple[np.ndarray, np.ndarray, float] | None = None  # V1, load1, R
        self._version = -1  # the solver's operator version that V1 belongs to
        self._derived: dict[str, np.ndarray] = {}  # of the cached V1 (``per_unit``)

    def cached_unit_field(
        self,
    ) -> tuple[ContactWeights, tuple[np.ndarray, np.ndarray, float]] | None:
        """(contact, (V1, load1, R)) of the cached unit-current field, if any."""
        if self._unit is None or self._contact is None:
            return None
        return self._contact, self._unit

    def restore_unit_field(
        self, contact: ContactWeights, unit: tuple[np.ndarray, np.ndarray, float]
    ) -> None:
        """Seed the cache (e.g. from a checkpoint); the conductivity must already be set."""
        self._contact, self._unit = contact, unit
        self._version = self.solver.version
        self._derived = {}

    def per_unit(self, name: str, make: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """A field derived linearly or quadratically from the cached unit-current field V1
        (``make(V1)``, e.g. its Joule heat), computed once per V1: a drive then scales it
        (I or I^2) instead of recomputing it every step the potential is reused."""
        if self._unit is None:
            raise SceneError("potential: per_unit before any unit field")
        value = self._derived.get(name)
        if value is None:
            value = self._derived[name] = make(self._unit[0])
        return value

    def unit_field(
        self, sigma: np.ndarray | float, contact: ContactWeights
    ) -> tuple[np.ndarray, np.ndarray, float, PotentialStats]:
        """(V1, load1, R, stats): potential and load at 1 A, resistance R in ohm."""
        self.solver.set_conductivity(sigma)
        up_to_date = self._version == self.solver.version and same_contact(contact, self._contact)
        if up_to_date and self._unit is not None:
            V1, load1, R = self._unit
            return V1, load1, R, PotentialStats(0, 0.0, 0.0, 0.0, 0.0, False, True)
        load1 = contact.weights / contact.area_m2
        V1, stats = self.solver.solve(load1)
        # the field's own dissipation at 1 A: a drive then puts exactly its power into the
        # tissue's Joule heat even where the guarded solve stopped at its energy tolerance
        R = self.solver.dissipation(V1)
        self._contact, self._unit = contact, (V1, load1, R)
        self._version = self.solver.version
        self._derived = {}
        return V1, load1, R, stats

    def solve(
        self, sigma: np.ndarray | float, contact: ContactWeights, drive: ElectrodeDrive
    ) -> PotentialSolution:
        """The potential for ``drive`` through ``contact`` in conductivity sigma (n_tets,)."""
        V1, load1, R, stats = self.unit_field(sigma, contact)
        current = drive_current(drive, contact.area_m2, R)
        return PotentialSolution(
            V=current * V1,
            load=current * load1,
            current_a=current,
            power_w=current**2 * R,
            stats=stats,
            resistance_ohm=R,
        )


def drive_current(drive: ElectrodeDrive, area_m2: float, resistance_ohm: float) -> float:
    """Injected current I in A: j * area (constant current density) or sqrt(P / R) (power),
    at most V_max / R where the generator's voltage limit ``max_voltage_v`` is set."""
    if drive.mode == "current_density":
        current = drive.current_density_a_per_m2 * area_m2
    else:
        if not resistance_ohm > 0:
            raise SolverDivergedError(
                f"potential: resistance between the electrodes is {resistance_ohm} ohm, so no "
                "current delivers the set power (does the contact touch the return electrode?)"
            )
        current = float(np.sqrt(drive.power_w / resistance_ohm))
    if drive.max_voltage_v is not None and current * resistance_ohm > drive.max_voltage_v:
        current = drive.max_voltage_v / resistance_ohm
    return current


def voltage_limited(drive: ElectrodeDrive, current_a: float, resistance_ohm: float) -> bool:
    """Whether the generator's voltage limit set ``current_a`` (below what the drive asked)."""
    v = drive.max_voltage_v
    return v is not None and current_a * resistance_ohm >= v * (1 - 1e-12)
