"""A structured grid of nodes over a box: shapes (nz, ny, nx), node coordinates and index maps.

A grid is uniform (equal spacing per axis, the default) or graded: per-axis node coordinates,
e.g. fine under the electrode and growing geometrically away from it (``Grid.graded``). Both
keep the structured (nz, ny, nx) node arrays; only the node positions differ.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from diathermy.errors import MeshError
from diathermy.mesh.grading import graded_axis

Axes = tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]
AxisLike = Sequence[float] | np.ndarray


@dataclass(frozen=True)
class Grid:
    """Nodes of a box [x0, x0+Lx] x [y0, y0+Ly] x [z0, z0+Lz], arrays shaped (nz, ny, nx).

    A node (k, j, i) has flat index ``(k * ny + j) * nx + i`` (C order of the shape), so
    ``field.reshape(grid.shape)`` turns a nodal vector into a grid-shaped array.

    ``node_axes_m`` (x, y, z node coordinates, each increasing from the origin to the far face)
    makes the grid graded; None (the default) is the uniform grid, whose behaviour and numbers
    do not depend on this option. Build graded grids with ``Grid.graded`` or ``Grid.from_axes``.
    """

    shape: tuple[int, int, int]
    size_m: tuple[float, float, float] = (0.2, 0.1, 0.1)  # (Lx, Ly, Lz)
    origin_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # (x0, y0, z0)
    node_axes_m: Axes | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if len(self.shape) != 3 or not all(_count_ok(n) for n in self.shape):
            raise MeshError(f"grid shape must be three node counts >= 2, got {self.shape}")
        if len(self.size_m) != 3 or any(not _finite(s) or float(s) <= 0 for s in self.size_m):
            raise MeshError(f"block size must be three positive lengths in m, got {self.size_m}")
        if len(self.origin_m) != 3 or not all(_finite(o) for o in self.origin_m):
            raise MeshError(
                f"block origin must be three finite coordinates in m, got {self.origin_m}"
            )
        object.__setattr__(self, "shape", tuple(int(n) for n in self.shape))
        if self.node_axes_m is not None:
            object.__setattr__(self, "node_axes_m", self._checked_axes(self.node_axes_m))

    def _checked_axes(self, axes: Sequence[Sequence[float]]) -> Axes:
        """Validate graded node coordinates against shape, origin and size; as float tuples."""
        if len(axes) != 3:
            raise MeshError("graded grid needs node coordinates for the 3 axes (x, y, z)")
        out = []
        for name, ax, n, o, size in zip(
            "xyz", axes, self.shape[::-1], self.origin_m, self.size_m, strict=True
        ):
            a = np.asarray(ax, dtype=float)
            if a.ndim != 1 or a.size != n:
                raise MeshError(f"{name} node coordinates must be {n} numbers, got shape {a.shape}")
            if not np.all(np.isfinite(a)) or np.any(np.diff(a) <= 0.0):
                raise MeshError(f"{name} node coordinates must be finite and strictly increasing")
            tol = 1e-9 * size
            if abs(a[0] - o) > tol or abs(a[-1] - (o + size)) > tol:
                raise MeshError(
                    f"{name} node coordinates must run from the origin {o} m to {o + size} m, "
                    f"got {a[0]} .. {a[-1]} m"
                )
            out.append(tuple(float(v) for v in a))
        return (out[0], out[1], out[2])

    @classmethod
    def from_axes(cls, x: AxisLike, y: AxisLike, z: AxisLike) -> Grid:
        """A graded grid with node coordinates x (nx,), y (ny,), z (nz,) in m, each increasing."""
        axes = [np.asarray(a, dtype=float) for a in (x, y, z)]
        for name, a in zip("xyz", axes, strict=True):
            if a.ndim != 1 or a.size < 2 or not np.all(np.isfinite(a)):
                raise MeshError(f"{name} node coordinates must be >= 2 finite numbers in m")
        shape = (axes[2].size, axes[1].size, axes[0].size)
        origin = tuple(float(a[0]) for a in axes)
        size = tuple(float(a[-1] - a[0]) for a in axes)
        return cls(shape, size_m=size, origin_m=origin, node_axes_m=tuple(axes))  # type: ignore[arg-type]

    @classmethod
    def graded(
        cls,
        region_lo_m: Sequence[float],
        region_hi_m: Sequence[float],
        fine_m: float | Sequence[float],
        *,
        growth: float = 1.2,
        max_cell_m: float | Sequence[float] = math.inf,
        top_cell_m: float | None = None,
        bottom_tier_m: tuple[float, float] | None = None,
        size_m: tuple[float, float, float] = (0.2, 0.1, 0.1),
        origin_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> Grid:
        """A grid uniform with cells <= fine_m over the working box [region_lo_m, region_hi_m].

        Outside the box (x, y, z in m) the cells grow by at most ``growth`` per cell, up to
        ``max_cell_m``; ``fine_m`` and ``max_cell_m`` are one length or one per axis (x, y, z).
        A box side within one fine cell of the block's face is extended to it. ``top_cell_m``:
        the box's cells shrink toward its top (z high) side to this length there, by at most
        ``growth`` per cell (None: uniform up to it). ``bottom_tier_m`` (length, cell): below the
        box, over that length, the cells grow in z only to that height before they grow on
        (None: no tier).
        """
        lo, hi = _triple("region_lo_m", region_lo_m), _triple("region_hi_m", region_hi_m)
        fine = _triple("fine_m", fine_m)
        cap = _triple("max_cell_m", max_cell_m)
        probe = cls((2, 2, 2), size_m=size_m, origin_m=origin_m)  # validates size and origin
        ends = (None, None, top_cell_m)
        tiers = (None, None, bottom_tier_m)
        axes = [
            graded_axis(o, o + s, (a, b), f, growth, c, hi_cell=e, lo_tier=t)
            for o, s, a, b, f, c, e, t in zip(
                probe.origin_m, probe.size_m, lo, hi, fine, cap, ends, tiers, strict=True
            )
        ]
        return cls.from_axes(*axes)

    @property
    def is_uniform(self) -> bool:
        """True for the uniform grid (one spacing per axis), False for a graded one."""
        return self.node_axes_m is None

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
        """The uniform node spacing (dx, dy, dz) in m.

        A graded grid has no single spacing and raises MeshError, so that code written for
        uniform grids fails loudly instead of using a wrong spacing: use ``cell_sizes_m`` (every
        cell) or ``min_spacing_m`` (the finest cell, e.g. for a CFL limit) there.
        """
        if self.node_axes_m is not None:
            raise MeshError(
                "a graded grid has no single node spacing: use cell_sizes_m() per cell or "
                "min_spacing_m for the finest"
            )
        return (
            self.size_m[0] / (self.nx - 1),
            self.size_m[1] / (self.ny - 1),
            self.size_m[2] / (self.nz - 1),
        )

    @property
    def min_spacing_m(self) -> tuple[float, float, float]:
        """The smallest cell length per axis (dx, dy, dz) in m (= spacing_m on a uniform grid)."""
        if self.node_axes_m is None:
            return self.spacing_m
        dx, dy, dz = self.cell_sizes_m()
        return (float(dx.min()), float(dy.min()), float(dz.min()))

    def cell_sizes_m(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cell lengths along x (nx-1,), y (ny-1,), z (nz-1,) in m."""
        if self.node_axes_m is None:
            dx, dy, dz = self.spacing_m
            return (np.full(self.nx - 1, dx), np.full(self.ny - 1, dy), np.full(self.nz - 1, dz))
        x, y, z = self.axes()
        return (np.diff(x), np.diff(y), np.diff(z))

    def axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Node coordinates along x (nx,), y (ny,), z (nz,) in m."""
        if self.node_axes_m is not None:
            ax, ay, az = self.node_axes_m
            return (np.array(ax), np.array(ay), np.array(az))
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
        if self.node_axes_m is not None:
            x, y, z = self.axes()
            i, j, k = (
                np.clip(np.searchsorted(a, xyz[:, c], side="right") - 1, 0, a.size - 2)
                for c, a in enumerate((x, y, z))
            )
            return k.astype(np.int64), j.astype(np.int64), i.astype(np.int64)
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


def _finite(v: object) -> bool:
    try:
        return math.isfinite(float(v))  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False


def _count_ok(n: object) -> bool:
    """A node count: an integer-valued number >= 2."""
    return _finite(n) and float(n) == int(float(n)) and int(float(n)) >= 2  # type: ignore[arg-type]


def _triple(name: str, value: float | Sequence[float]) -> tuple[float, float, float]:
    """One value or three (x, y, z) as three floats."""
    try:
        v = np.atleast_1d(np.asarray(value, dtype=float))
    except (TypeError, ValueError):
        raise MeshError(f"{name} must be one number or three (x, y, z), got {value!r}") from None
    if v.size == 1:
        v = np.repeat(v, 3)
    if v.shape != (3,) or np.any(np.isnan(v)):
        raise MeshError(f"{name} must be one number or three (x, y, z), got {value!r}")
    return (float(v[0]), float(v[1]), float(v[2]))
