"""The mutable state of a simulation: every field, the clock, the energy ledger, the electrode
overrides, and what the effects remember between steps (named, never hidden attributes)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from diathermy.engine.electrodes import ElectrodeOverride
from diathermy.engine.ledger import EnergyLedger
from diathermy.physics.materials import Tissue
from diathermy.physics.topology import Topology

NODAL_FIELDS = (
    "potential",
    "temperature",
    "pressure",
    "vapor_fraction",
    "level_set",
    "thermal_damage",
)
VECTOR_FIELDS = ("displacement",)
CELL_FIELDS = ("joule_heat", "strain_energy", "removed")

ContactKey = tuple[float, ...]
"""A contact disk: centre (x, y, z) and radius, in m; a draped disk adds the height (m) of each
of its quadrature points (NaN: no tissue under the point)."""


@dataclass
class EffectMemory:
    """What effects carry from one step to the next besides the fields.

    steps_since_reinit: dissection steps since the level set was last re-initialised.
    mechanics_key: the (pressure, removed, tissue share) bytes the displacement was solved for,
        None when u is not the solution of the current state.
    topology: the last topology the dissection evaluated (removed and loose tets, crater).
    contacts: the contact disks the electric effect used last step (empty: none).
    """

    steps_since_reinit: int = 0
    mechanics_key: tuple[bytes, bytes, bytes] | None = None
    topology: Topology | None = None
    contacts: tuple[ContactKey, ...] = ()


@dataclass
class SimulationState:
    """All that a step reads and writes. Arrays are flat over nodes (n,) / (n, 3) or tets (m,).

    Units: potential V, temperature K, pressure Pa (absolute), vapor_fraction (mass fraction of the
    water), level_set m, thermal_damage (Arrhenius Omega, dimensionless), displacement m,
    joule_heat W/m^3, strain_energy J/m^3, removed (bool per tet).
    """

    step: int
    time_s: float
    arrays: dict[str, np.ndarray]
    energy: EnergyLedger = field(default_factory=EnergyLedger)
    overrides: dict[str, ElectrodeOverride] = field(default_factory=dict)
    memory: EffectMemory = field(default_factory=EffectMemory)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.arrays[name]

    def __setitem__(self, name: str, value: np.ndarray) -> None:
        self.arrays[name] = value


def initial_state(
    n_nodes: int, n_tets: int, z_nodes: np.ndarray, top_z: float, tissue: Tissue
) -> SimulationState:
    """The state at t = 0: body temperature, no vapor, atmospheric pressure, nothing cut.

    The level set starts as the signed distance to the top surface, ``top_z - z`` (m).
    """
    arrays = {
        "potential": np.zeros(n_nodes),
        "temperature": np.full(n_nodes, tissue.t_initial_k),
        "pressure": np.full(n_nodes, tissue.p_atm_pa),
        "vapor_fraction": np.zeros(n_nodes),
        "level_set": top_z - z_nodes,
        "thermal_damage": np.zeros(n_nodes),
        "displacement": np.zeros((n_nodes, 3)),
        "joule_heat": np.zeros(n_tets),
        "strain_energy": np.zeros(n_tets),
        "removed": np.zeros(n_tets, dtype=bool),
    }
    return SimulationState(step=0, time_s=0.0, arrays=arrays)
