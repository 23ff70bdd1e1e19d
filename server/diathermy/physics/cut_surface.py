"""The cut surface phi = 0 as a triangle mesh (marching cubes), for display and export."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import meshio
import numpy as np
from skimage.measure import marching_cubes

from diathermy.mesh.grid import Grid


@dataclass(frozen=True)
class CutSurface:
    """Triangles of the cut: vertices (n, 3) as (x, y, z) in m, faces (m, 3) of vertex indices.

    Faces are wound so that their right-hand normals point out of the healthy tissue, into the
    removed region.
    """

    vertices: np.ndarray
    faces: np.ndarray

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    def area_m2(self) -> float:
        """Total triangle area in m^2."""
        v = self.vertices[self.faces]
        return float(
            0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1).sum()
        )


def empty_surface() -> CutSurface:
    return CutSurface(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))


def cut_surface(phi: np.ndarray, grid: Grid) -> CutSurface:
    """The phi = 0 surface between removed (phi < 0) and healthy (phi >= 0) nodes.

    Marching cubes runs on -phi over the bounding box of the removed nodes (plus one layer), so
    nodes with phi = 0 (the untouched original top) count as healthy and yield no surface, and
    the work scales with the cut, not the block. Empty (0 vertices) when nothing is removed.
    Vertices come from skimage in float32: good to ~1e-9 m on a 0.2 m block. Marching cubes
    interpolates along grid edges only, so it may differ from the P1 zero set on the Kuhn tets
    (``topology``) by a fraction of a cell where the surface is curved.
    """
    phi = np.asarray(phi, dtype=float).reshape(grid.shape)
    neg = phi < 0
    if not neg.any():
        return empty_surface()
    lo = [
        max(int(np.flatnonzero(neg.any(axis=ax)).min()) - 1, 0) for ax in ((1, 2), (0, 2), (0, 1))
    ]
    hi = [int(np.flatnonzero(neg.any(axis=ax)).max()) + 2 for ax in ((1, 2), (0, 2), (0, 1))]
    box = -phi[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]]
    if not (box <= 0).any():  # nothing healthy left around the cut
        return empty_surface()
    if not grid.is_uniform:  # marching cubes in index space, vertices mapped onto the axes
        verts, faces, _, _ = marching_cubes(box, 0.0, allow_degenerate=False)
        xyz = [
            np.interp(verts[:, c] + lo[c], np.arange(a.size), a)
            for c, a in enumerate(grid.axes()[::-1])
        ]
        return CutSurface(np.column_stack(xyz[::-1]), faces[:, ::-1].astype(np.int64))
    dx, dy, dz = grid.spacing_m
    verts, faces, _, _ = marching_cubes(box, 0.0, spacing=(dz, dy, dx), allow_degenerate=False)
    x0, y0, z0 = grid.origin_m
    offset = np.array([x0 + lo[2] * dx, y0 + lo[1] * dy, z0 + lo[0] * dz])
    # (z, y, x) -> (x, y, z) is a reflection, so the winding flips back to healthy -> removed.
    return CutSurface(verts[:, ::-1] + offset, faces[:, ::-1].astype(np.int64))


def write_cut_surface(path: str | Path, surface: CutSurface) -> None:
    """Write the surface with meshio; the format follows the suffix (.vtu, .ply, .stl, ...)."""
    meshio.Mesh(surface.vertices, [("triangle", surface.faces)]).write(str(path))
