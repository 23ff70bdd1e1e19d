"""Re-initialisation of the level set to a signed distance that keeps the cut where it is.

Uniform grids use scikit-fmm; graded grids fast sweeping on the node coordinates
(``physics.rectilinear_distance`` via ``physics.levelset_graded``). The rule that keeps every
node's sign and never raises phi next to the front is the same for both (see ``reinitialize``).
"""

from __future__ import annotations

import math
from typing import cast

import numpy as np
import scipy.ndimage as ndi
import skfmm

from diathermy.physics import levelset_graded as graded
from diathermy.physics.levelset_graded import CellSizes
from diathermy.physics.levelset_law import REINIT_BAND_CELLS

Spacing = tuple[float, float, float]
"""Node spacing (dx, dy, dz) in m; arrays are (z, y, x)."""


def reinitialize(
    phi: np.ndarray,
    spacing: Spacing | CellSizes,
    *,
    band_cells: float | None = REINIT_BAND_CELLS,
) -> np.ndarray:
    """Back to a signed distance (nz, ny, nx) in m, keeping the cut where it is (scikit-fmm).

    d = skfmm.distance(phi) puts the zero set where linear interpolation of phi puts it. The rule:
    - every node keeps its sign (removed stays removed, healthy stays healthy);
    - a node within one cell of healthy tissue (some node of its 3x3x3 block is >= 0), and every
      healthy node, gets min(d, phi): its phi never rises, so no tet the front cuts ever gets
      less removed (the P1 removed volume never shrinks);
    - a removed node whose whole 3x3x3 block is removed ("deep") gets d: every tet around it stays
      fully removed whatever its value, and resetting it stops the removed side from steepening
      without bound (min(d, phi) everywhere did that and left a front driven by F = a + b z,
      re-initialised every step, 0.5-0.9 cells ahead of the exact one; this rule: < 0.06 cells).
    band_cells: only nodes within that many cells (of the largest spacing) of the front are
    touched, and only around the removed region (the untouched top is a distance already); None
    does the whole block. A block with no healthy or no removed node is returned unchanged.
    On a graded grid (``spacing`` the cell lengths per axis) d comes from fast sweeping on the
    node coordinates (``physics.rectilinear_distance``) and the band is counted in the largest
    cell around the removed region (the cells the front crosses; the block's largest, up to
    6x the working region's on the default grids, made the band the whole block); the rule is
    the same.
    """
    phi = np.asarray(phi, dtype=float)
    if not ((phi < 0).any() and (phi > 0).any()):
        return phi.copy()
    box: tuple[slice, ...]
    if graded.is_graded(spacing):
        coords = graded.node_coordinates(spacing)  # type: ignore[arg-type]
        if band_cells is None:
            narrow, box = 0.0, (slice(None),) * 3
        else:  # the band in the front's cells: the block's largest made it the whole block
            front = graded.around_removed(phi, coords, 0.0)
            narrow = band_cells * graded.largest_cell(spacing, front)  # type: ignore[arg-type]
            box = graded.around_removed(phi, coords, 2 * narrow)
        sub = np.ascontiguousarray(phi[box])
        d = graded.banded_distance(sub, [c[b] for c, b in zip(coords, box, strict=True)], narrow)
    else:
        h = cast(Spacing, spacing)
        h_zyx = (h[2], h[1], h[0])
        narrow = 0.0 if band_cells is None else band_cells * max(h)
        box = (slice(None),) * 3 if band_cells is None else _around_removed(phi, h_zyx, 2 * narrow)
        sub = np.ascontiguousarray(phi[box])  # skfmm misreads strided views
        d = skfmm.distance(sub, dx=h_zyx, narrow=narrow)
        d = np.ma.filled(d, np.nan) if np.ma.isMaskedArray(d) else np.asarray(d)
    deep = ndi.maximum_filter(sub, size=3, mode="nearest") < 0
    new_sub = np.where(deep, d, np.minimum(d, sub))
    keep = np.isnan(new_sub) | (np.sign(new_sub) != np.sign(sub))
    new_sub[keep] = sub[keep]
    new = phi.copy()
    new[box] = new_sub
    return new


def _around_removed(phi: np.ndarray, h_zyx: Spacing, margin: float) -> tuple[slice, ...]:
    """The bounding box of the removed nodes grown by margin (m) plus two nodes per side.

    Outside it phi >= 0 and, with margin >= 2 x the band, every zero of phi within the band of a
    node inside (the crater, or the untouched top right above it) lies inside it too.
    """
    neg = phi < 0
    box = []
    for ax, h in enumerate(h_zyx):
        idx = np.flatnonzero(neg.any(axis=tuple(a for a in range(3) if a != ax)))
        pad = math.ceil(margin / h) + 2
        box.append(slice(max(int(idx[0]) - pad, 0), int(idx[-1]) + pad + 1))
    return tuple(box)
