"""Field access: which fields a scene's effects produce, grid-shaped copies of them."""

from __future__ import annotations

import numpy as np

from diathermy.engine.discretization import Discretization
from diathermy.engine.state import CELL_FIELDS, NODAL_FIELDS, SimulationState
from diathermy.errors import SceneError

FIELD_NAMES = (*NODAL_FIELDS, "displacement", *CELL_FIELDS)

NODAL_OUTPUT = (
    ("electric", "potential"),
    ("thermal", "temperature"),
    ("vaporization", "pressure"),
    ("vaporization", "vapor_fraction"),
    ("mechanics", "displacement"),
    ("dissection", "level_set"),
    ("thermal_damage", "thermal_damage"),
)
"""(effect, nodal field) in run-file order: a field is written when its effect is in the scene."""

CELL_OUTPUT = (
    ("electric", "joule_heat"),
    ("mechanics", "strain_energy"),
    ("dissection", "removed"),
)


def field(disc: Discretization, state: SimulationState, name: str) -> np.ndarray:
    """A copy of one field: nodal grid-shaped (nz, ny, nx[, 3]) or per tet (n_tets,)."""
    if name not in FIELD_NAMES:
        raise SceneError(f"unknown field {name!r}; fields: {', '.join(FIELD_NAMES)}")
    value = state[name]
    if name in CELL_FIELDS:
        return value.copy()
    return disc.to_grid(value).copy()


def nodal_fields(
    disc: Discretization, state: SimulationState, effects: tuple[str, ...]
) -> dict[str, np.ndarray]:
    """The nodal fields of the scene's effects, grid-shaped, for run files."""
    return {n: field(disc, state, n) for e, n in NODAL_OUTPUT if e in effects}


def cell_fields(state: SimulationState, effects: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The per-tet fields of the scene's effects (removed as uint8), for run files."""
    out = {n: state[n].copy() for e, n in CELL_OUTPUT if e in effects}
    if "removed" in out:
        out["removed"] = out["removed"].astype(np.uint8)
    return out


def dof_counts(disc: Discretization, effects: tuple[str, ...]) -> dict[str, int]:
    """Unknowns per field of the scene's effects."""
    n, fixed = disc.n_nodes, disc.bottom_nodes.size
    counts = {
        "electric": ("potential", n - fixed),
        "thermal": ("temperature", n),
        "mechanics": ("displacement", 3 * (n - fixed)),
        "dissection": ("level_set", n),
    }
    return dict(v for e, v in counts.items() if e in effects)
