"""Per-tet values of nodal fields on a Kuhn mesh (gradients, means) from slices of the node grid.

A Kuhn tet runs 000 -> e_a -> e_a + e_b -> 111 through its cell, so its gradient along axis a is
the difference of the field along the one a-edge of the cell that the path takes, over the
cell's length, and its mean is that of the 4 cell corners on the path. Differences and corner
values of the nodal grid, sliced per shape, give every tet's value without a gather or a stored
sparse operator (the gradient matrix's 6 entries per tet took 80 MB on the fixed electrode's
958 k tets, the tet-mean matrix's 4 about 50 MB, and each product read them all).
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


def tet_mean(f: np.ndarray, grid: Grid) -> np.ndarray:
    """The mean of a nodal scalar f (n_nodes,) over each tet's 4 nodes (n_tets,), TetMesh order:
    the cell's 000 and 111 corners, which every shape shares, and the shape's two others."""
    nz, ny, nx = grid.shape
    cz, cy, cx = nz - 1, ny - 1, nx - 1
    g = np.asarray(f, dtype=float).reshape(nz, ny, nx)

    def corner(ox: int, oy: int, oz: int) -> np.ndarray:
        return g[oz : oz + cz, oy : oy + cy, ox : ox + cx]

    ends = corner(0, 0, 0) + corner(1, 1, 1)
    out = np.empty((6, cz, cy, cx))  # shape first: contiguous writes, one transposing copy
    for s, corners in enumerate(kuhn_corners()):
        a, b = (tuple(int(v) for v in c) for c in corners if 0 < c.sum() < 3)
        np.add(ends, corner(*a), out=out[s])
        out[s] += corner(*b)
    out *= 0.25
    return shapes_last(out)


def shapes_last(by_shape: np.ndarray) -> np.ndarray:
    """(6, cz, cy, cx) per shape -> (n_tets,) in TetMesh order (tet 6 cell + shape)."""
    return np.moveaxis(by_shape, 0, -1).reshape(-1)
