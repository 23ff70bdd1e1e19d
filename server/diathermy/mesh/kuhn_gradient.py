"""Per-tet gradients of nodal fields on a Kuhn mesh, from node differences along the grid axes.

A Kuhn tet runs 000 -> e_a -> e_a + e_b -> 111 through its cell, so its gradient along axis a is
the difference of the field along the one a-edge of the cell that the path takes, over the
cell's length. The differences of the nodal field along each axis, sliced per shape, give every
tet's gradient without a gather or a sparse product (the gradient matrix's 6 entries per tet
took 80 MB on the fixed electrode's 958 k tets, and each product read them all).
"""

from __future__ import annotations

from functools import cache

import numpy as np

from diathermy.mesh.grid import Grid
from diathermy.mesh.tet_mesh import kuhn_corners


@cache
def kuhn_step_corners() -> np.ndarray:
    """(6, 3, 3) int: [s, a] is the cell corner (ox, oy, oz) from which the path of Kuhn shape s
    steps along axis a (x, y, z)."""
    out = np.zeros((6, 3, 3), dtype=np.int64)
    for s, corners in enumerate(kuhn_corners()):
        path = corners[np.argsort(corners.sum(axis=1))]  # 000, e_a, e_a + e_b, 111
        for start, end in zip(path[:-1], path[1:], strict=True):
            out[s, int(np.argmax(end - start))] = start
    out.setflags(write=False)
    return out


def axis_differences(f: np.ndarray, grid: Grid) -> list[np.ndarray]:
    """df/dx, df/dy, df/dz of a nodal scalar f (n_nodes,) along each cell edge: arrays on the
    grid's (z, y, x) axes, one shorter along their own axis, in units of f per m."""
    nz, ny, nx = grid.shape
    g = np.asarray(f, dtype=float).reshape(nz, ny, nx)
    hx, hy, hz = grid.cell_sizes_m()
    return [
        np.diff(g, axis=2) / hx,
        np.diff(g, axis=1) / hy[:, None],
        np.diff(g, axis=0) / hz[:, None, None],
    ]


def shape_gradient(diffs: list[np.ndarray], shape: int) -> list[np.ndarray]:
    """[df/dx, df/dy, df/dz] (each (cz, cy, cx), views) on the tets of Kuhn shape ``shape`` of
    every cell, from ``axis_differences``; tet ``6 cell + shape`` of the TetMesh order."""
    cz, cy, cx = diffs[0].shape[0] - 1, diffs[0].shape[1] - 1, diffs[0].shape[2]
    out = []
    for a, (ox, oy, oz) in enumerate(kuhn_step_corners()[shape]):
        out.append(diffs[a][oz : oz + cz, oy : oy + cy, ox : ox + cx])
    return out


def per_tet(values: np.ndarray | float, grid: Grid) -> np.ndarray:
    """A per-tet quantity (n_tets,) or one number as (cz, cy, cx, 6): cell, then shape."""
    cz, cy, cx = (n - 1 for n in grid.shape)
    return np.broadcast_to(np.asarray(values, dtype=float), (cz * cy * cx * 6,)).reshape(
        cz, cy, cx, 6
    )
