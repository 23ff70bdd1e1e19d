"""A structured grid of nodes over a box: shapes (nz, ny, nx), spacing and index maps."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diathermy.errors import MeshError


@dataclass(frozen=True)
class Grid:
    """Nodes of a box [x0, x0+Lx] x [y0, y0+Ly] x [z0, z0+Lz], arrays shaped (nz, ny, nx).

    A node (k, j, i) has flat index ``(k * ny + j) * nx + i`` (C order of the shape), so
    ``field.reshape(grid.shape)`` turns a nodal vector into a grid-shaped array.
    """

    shape: tuple[int, int, int]
    size_m: tuple[float, float, float] = (0.2, 0.1, 0.1)  # (Lx, Ly, Lz)
    origin_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # (x0, y0, z0)

    def __post_init__(self) -> None:
        if len(self.shape) != 3 or any(int(n) < 2 for n in self.shape):
            raise MeshError(f"grid shape must be three node counts >= 2, got {self.shape}")
        if len(self.size_m) != 3 or any(not np.isfinite(s) or s <= 0 for s in self.size_m):
            raise MeshError(f"block size must be three positive lengths in m, got {self.size_m}")
        object.__setattr__(self, "shape", tuple(int(n) for n in self.shape))

    @property
    def nz(self) -> int:
        return self.shape[0]

    @property
    def ny(self) -> int:
        return self.shape[1]

    @property
    def nx(self) -> int:
        return self.shape[2]

    @property
    def n_nodes(self) -> int:
        return self.nz * self.ny * self.nx

    @property
    def n_cells(self) -> int:
        return (self.nz - 1) * (self.ny - 1) * (self.nx - 1)

    @property
    def spacing_m(self) -> tuple[float, float, float]:
        """Node spacing (dx, dy, dz) in m."""
        return (
            self.size_m[0] / (self.nx - 1),
            self.size_m[1] / (self.ny - 1),
            self.size_m[2] / (self.nz - 1),
        )

    def axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Node coordinates along x (nx,), y (ny,), z (nz,) in m."""
        (x0, y0, z0), (lx, ly, lz) = self.origin_m, self.size_m
        return (
            np.linspace(x0, x0 + lx, self.nx),
            np.linspace(y0, y0 + ly, self.ny),
            np.linspace(z0, z0 + lz, self.nz),
        )

    def points(self) -> np.ndarray:
        """Node coordinates (n_nodes, 3) as (x, y, z) in m, in flat node order."""
        x, y, z = self.axes()
        zz, yy, xx = np.meshgrid(z, y, x, indexing="ij")
        return np.column_stack([xx.ravel(), yy.ravel(), zz.ravel()])

    def flat_index(self, k: np.ndarray, j: np.ndarray, i: np.ndarray) -> np.ndarray:
        """Flat node index of grid indices (k, j, i)."""
        return (np.asarray(k) * self.ny + np.asarray(j)) * self.nx + np.asarray(i)

    def grid_index(self, node: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Grid indices (k, j, i) of flat node indices."""
        k, rest = np.divmod(np.asarray(node), self.ny * self.nx)
        j, i = np.divmod(rest, self.nx)
        return k, j, i

    def cell_of(self, xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cell indices (k, j, i) containing points (n, 3), clamped into the block."""
        xyz = np.atleast_2d(np.asarray(xyz, dtype=float))
        dx, dy, dz = self.spacing_m
        x0, y0, z0 = self.origin_m
        i = np.clip(np.floor((xyz[:, 0] - x0) / dx), 0, self.nx - 2).astype(np.int64)
        j = np.clip(np.floor((xyz[:, 1] - y0) / dy), 0, self.ny - 2).astype(np.int64)
        k = np.clip(np.floor((xyz[:, 2] - z0) / dz), 0, self.nz - 2).astype(np.int64)
        return k, j, i

    def contains(self, xyz: np.ndarray, tol: float = 1e-12) -> np.ndarray:
        """Boolean mask of points (n, 3) inside the closed block."""
        xyz = np.atleast_2d(np.asarray(xyz, dtype=float))
        lo = np.asarray(self.origin_m) - tol
        hi = np.asarray(self.origin_m) + np.asarray(self.size_m) + tol
        return np.all((xyz >= lo) & (xyz <= hi), axis=1)
