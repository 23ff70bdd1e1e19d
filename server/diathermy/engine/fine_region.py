"""Whether what the physics hinges on stays where the grid is fine.

A graded grid is fine only over the scene's working region (``resolution``); a crater that digs
below it, a path moved off it by a client, or vapor spreading past it lands on cells that grow
geometrically away from it, and the results there carry the coarse grid's error
(docs/resolution.md). Each step report says how far the cut, the vapor and the thermal lesion
reach beyond the region, so that a run cannot leave it unnoticed.
"""

from __future__ import annotations

import numpy as np

from diathermy.mesh import Grid
from diathermy.scene.resolution import Box


def box_excess_m(grid: Grid, nodal_mask: np.ndarray, box: Box) -> float:
    """How far in m the nodes of ``nodal_mask`` (n_nodes,) reach beyond ``box``: the largest
    excess along any axis of the nodes' bounding box (0 when none lies outside, or none is set).
    A node on the box's face is inside (excess within 1e-9 of the block's size counts as 0)."""
    mask = np.asarray(nodal_mask, dtype=bool).reshape(grid.shape)  # (nz, ny, nx)
    if not mask.any():
        return 0.0
    tol = 1e-9 * max(grid.size_m)
    excess = tol
    for axis, coords in enumerate(grid.axes()):  # x, y, z
        other = tuple(a for a in range(3) if a != 2 - axis)
        hit = np.flatnonzero(mask.any(axis=other))
        lo, hi = coords[hit[0]], coords[hit[-1]]
        excess = max(excess, box[0][axis] - lo, hi - box[1][axis])
    return float(excess) if excess > tol else 0.0


LESION_OMEGA = 1.0
"""The Arrhenius damage integral at the lesion's edge (1 - e^-1 = 63 % of the cells dead)."""


def beyond_fine_region(
    grid: Grid,
    box: Box | None,
    level_set: np.ndarray,
    vapor_fraction: np.ndarray,
    thermal_damage: np.ndarray,
) -> dict[str, float]:
    """How far in m the cut (phi < 0), the vapor (x > 0) and the lesion (Omega >= 1) reach
    beyond the working region ``box``; empty on a grid without one (uniform: equally fine
    everywhere). Nodal arrays (n_nodes,)."""
    if box is None:
        return {}
    return {
        "cut": box_excess_m(grid, level_set < 0, box),
        "vapor": box_excess_m(grid, vapor_fraction > 0, box),
        "lesion": box_excess_m(grid, thermal_damage >= LESION_OMEGA, box),
    }
