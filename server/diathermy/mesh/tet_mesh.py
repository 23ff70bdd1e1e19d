"""The conforming tetrahedral mesh of a structured grid: 6 Kuhn tetrahedra per hexahedral cell.

Every cell is split along its main diagonal into the 6 tetrahedra ``000 -> e_a -> e_a+e_b -> 111``
over the permutations (a, b, c) of the axes. The split is translation invariant, so neighbouring
cells share face diagonals and the mesh conforms. Vertices are ordered for positive volume.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import permutations

import numpy as np

from diathermy.mesh.grid import Grid

SIDES = ("x-", "x+", "y-", "y+", "z-", "z+")
"""Boundary sides; ``z-`` is the bottom (dispersive electrode), ``z+`` the traction-free top."""


def kuhn_corners() -> np.ndarray:
    """Corner offsets (6, 4, 3) as (ox, oy, oz) bits of the 6 Kuhn tetrahedra, positively oriented."""
    out = []
    for perm in permutations(range(3)):
        corner = np.zeros(3, dtype=np.int64)
        verts = [corner.copy()]
        for axis in perm:
            corner[axis] = 1
            verts.append(corner.copy())
        v = np.array(verts)
        if np.linalg.det((v[1:] - v[0]).astype(float)) < 0:
            v[[2, 3]] = v[[3, 2]]
        out.append(v)
    return np.array(out)


@dataclass(frozen=True)
class TetMesh:
    """Linear tetrahedra over a structured grid.

    Attributes:
        grid: the node grid.
        points: node coordinates (n_nodes, 3) in m.
        tets: node indices (n_tets, 4); tet ``6 * cell + s`` is Kuhn shape ``s`` of ``cell``.
        shape_id: Kuhn shape (n_tets,) in 0..5; tets of one shape are translates of each other
            on a uniform grid, and scaled per axis by their cell's size on a graded one.
        neighbours: face neighbour (n_tets, 4) across the face opposite each vertex, -1 on the boundary.
        boundary_faces: per side, triangles (n_faces, 3) of node indices.
    """

    grid: Grid
    points: np.ndarray
    tets: np.ndarray
    shape_id: np.ndarray
    neighbours: np.ndarray
    boundary_faces: dict[str, np.ndarray] = field(repr=False)

    @property
    def n_nodes(self) -> int:
        return int(self.points.shape[0])

    @property
    def n_tets(self) -> int:
        return int(self.tets.shape[0])

    def surface_triangles(self) -> np.ndarray:
        """All boundary triangles (n, 3), sides in the order of ``SIDES``."""
        return np.concatenate([self.boundary_faces[s] for s in SIDES])

    def side_nodes(self, side: str) -> np.ndarray:
        """Sorted unique node indices on one boundary side."""
        return np.unique(self.boundary_faces[side])

    def centroids(self) -> np.ndarray:
        """Tet centroids (n_tets, 3) in m."""
        return self.points[self.tets].mean(axis=1)

    def cell_tets(self, k: np.ndarray, j: np.ndarray, i: np.ndarray) -> np.ndarray:
        """The 6 tet indices (n, 6) of cells (k, j, i)."""
        g = self.grid
        cell = (np.asarray(k) * (g.ny - 1) + np.asarray(j)) * (g.nx - 1) + np.asarray(i)
        return 6 * np.asarray(cell)[..., None] + np.arange(6)

    def tets_touching(self, nodes: np.ndarray) -> np.ndarray:
        """Sorted indices of the tets that have at least one of ``nodes`` (flat node indices) as
        a vertex: from the up to 8 cells around each node, no search over the mesh."""
        nodes = np.asarray(nodes, dtype=np.int64).ravel()
        if nodes.size == 0:
            return np.zeros(0, dtype=np.int64)
        g = self.grid
        k, j, i = g.grid_index(nodes)
        step = np.array([-1, 0])
        cells = []
        for a, n in ((k, g.nz), (j, g.ny), (i, g.nx)):
            c = a[:, None] + step  # the cells below and above the node along this axis
            cells.append(np.where((c >= 0) & (c < n - 1), c, -1))
        ck = cells[0][:, :, None, None]
        cj = cells[1][:, None, :, None]
        ci = cells[2][:, None, None, :]
        valid = ((ck >= 0) & (cj >= 0) & (ci >= 0)).ravel()
        shape = (nodes.size, 2, 2, 2)
        cand = self.cell_tets(
            np.broadcast_to(ck, shape).ravel()[valid],
            np.broadcast_to(cj, shape).ravel()[valid],
            np.broadcast_to(ci, shape).ravel()[valid],
        )
        cand = np.unique(cand)
        mark = np.zeros(self.n_nodes, dtype=bool)
        mark[nodes] = True
        return cand[mark[self.tets[cand]].any(axis=1)]

    def locate(self, xyz: np.ndarray, tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
        """Containing tet (n,) and barycentric coordinates (n, 4) of points (n, 3) in the block.

        Points outside the block are clamped to the nearest cell and may get coordinates
        outside [0, 1]; use ``grid.contains`` first where that matters.
        """
        xyz = np.atleast_2d(np.asarray(xyz, dtype=float))
        cand = self.cell_tets(*self.grid.cell_of(xyz))  # (n, 6)
        bary = barycentric(self.points[self.tets[cand]], xyz[:, None, :])  # (n, 6, 4)
        best = np.argmax(bary.min(axis=2), axis=1)
        rows = np.arange(xyz.shape[0])
        lam = bary[rows, best]
        lam = np.where(np.abs(lam) < tol, 0.0, lam)
        return cand[rows, best], lam


def barycentric(verts: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (..., 4) of points (..., 3) in tets with vertices (..., 4, 3)."""
    T = np.swapaxes(verts[..., 1:, :] - verts[..., :1, :], -1, -2)  # (..., 3, 3) columns v_i - v_0
    rhs = np.broadcast_to(xyz - verts[..., 0, :], T.shape[:-1])
    lam = np.linalg.solve(T, rhs[..., None])[..., 0]
    return np.concatenate([1.0 - lam.sum(axis=-1, keepdims=True), lam], axis=-1)


def build_tet_mesh(grid: Grid) -> TetMesh:
    """Build the 6-tets-per-cell mesh of ``grid`` with its boundary faces and face neighbours."""
    nz, ny, nx = grid.shape
    k, j, i = np.meshgrid(np.arange(nz - 1), np.arange(ny - 1), np.arange(nx - 1), indexing="ij")
    base = grid.flat_index(k, j, i).ravel()  # (n_cells,)
    corners = kuhn_corners()  # (6, 4, 3) as (ox, oy, oz)
    offset = corners[..., 2] * ny * nx + corners[..., 1] * nx + corners[..., 0]  # (6, 4)
    tets = (base[:, None, None] + offset[None]).reshape(-1, 4)
    shape_id = np.tile(np.arange(6, dtype=np.int8), base.size)
    neighbours, bfaces = _faces(tets, grid)
    return TetMesh(grid, grid.points(), tets, shape_id, neighbours, bfaces)


def _faces(tets: np.ndarray, grid: Grid) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Face neighbours (n_tets, 4) and boundary triangles by side."""
    n_tets = tets.shape[0]
    opposite = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
    faces = tets[:, opposite].reshape(-1, 3)  # face f of tet t at row 4 t + f
    s = np.sort(faces, axis=1).astype(np.int64)
    n = np.int64(grid.n_nodes)
    key = (s[:, 0] * n + s[:, 1]) * n + s[:, 2]
    order = np.argsort(key, kind="stable")
    ks = key[order]
    same = ks[1:] == ks[:-1]
    a, b = order[:-1][same], order[1:][same]
    neighbours = np.full(4 * n_tets, -1, dtype=np.int64)
    neighbours[a] = b // 4
    neighbours[b] = a // 4
    neighbours = neighbours.reshape(n_tets, 4)
    boundary = faces[neighbours.ravel() < 0]
    kk, jj, ii = grid.grid_index(boundary)
    bfaces: dict[str, np.ndarray] = {}
    for side, idx, last in (
        ("x-", ii, None),
        ("x+", ii, grid.nx - 1),
        ("y-", jj, None),
        ("y+", jj, grid.ny - 1),
        ("z-", kk, None),
        ("z+", kk, grid.nz - 1),
    ):
        value = 0 if last is None else last
        bfaces[side] = boundary[np.all(idx == value, axis=1)]
    return neighbours, bfaces
