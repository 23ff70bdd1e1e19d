"""The level set's pieces that differ on a graded (rectilinear) grid: per-node spacings, the
Godunov gradient with unequal one-sided spacings, the CFL rate from the local spacing, and the
signed distance for re-initialisation (scikit-fmm takes one spacing per axis; fast sweeping
on the node coordinates instead). ``physics.levelset`` dispatches here for graded grids.

Arrays are (nz, ny, nx); per-axis tuples run (z, y, x) unless named (x, y, z).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from diathermy.physics.rectilinear_distance import signed_distance

CellSizes = tuple[np.ndarray, np.ndarray, np.ndarray]
"""Cell lengths per axis (dx (nx-1,), dy (ny-1,), dz (nz-1,)) in m, as ``Grid.cell_sizes_m()``."""


def is_graded(spacing: Sequence[float] | Sequence[np.ndarray]) -> bool:
    """Whether a spacing argument holds cell lengths per axis (graded) rather than 3 numbers."""
    return bool(np.ndim(spacing[0]) == 1)


def node_spacings(
    shape: tuple[int, ...], active: np.ndarray, cells_xyz: Sequence[np.ndarray]
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Spacings (m) from each active flat node to its - and + neighbour per axis (z, y, x).

    At a block face the missing side mirrors the inner one (the ghost node's spacing).
    """
    strides = (shape[1] * shape[2], shape[2], 1)
    h_minus, h_plus = [], []
    for n, s, cells in zip(shape, strides, tuple(cells_xyz)[::-1], strict=True):
        c = (active // s) % n
        d = np.asarray(cells, dtype=float)
        h_minus.append(d[np.maximum(c - 1, 0)])
        h_plus.append(d[np.minimum(c, n - 2)])
    return h_minus, h_plus


def cfl_rate(F_active: np.ndarray, h_minus: list[np.ndarray], h_plus: list[np.ndarray]) -> float:
    """Largest F sum_a 1 / h_a (1/s) over the active nodes, h_a the node's smaller spacing."""
    inv = sum(1.0 / np.minimum(hm, hp) for hm, hp in zip(h_minus, h_plus, strict=True))
    return float((F_active * inv).max())


def godunov_gradient(
    flat: np.ndarray,
    center: np.ndarray,
    minus: Sequence[np.ndarray],
    plus: Sequence[np.ndarray],
    at_lo: Sequence[np.ndarray],
    at_hi: Sequence[np.ndarray],
    h_minus: Sequence[np.ndarray],
    h_plus: Sequence[np.ndarray],
    ghost_slope_cap: float,
) -> np.ndarray:
    """|grad phi| at the active nodes, Godunov upwind for F >= 0, with one-sided spacings.

    The same flux as the uniform scheme: per axis r = max(D-, -D+, 0), |grad phi|^2 = sum r^2,
    D- = (phi_c - phi_-) / h-, D+ = (phi_+ - phi_c) / h+; a face's ghost slope capped.
    """
    pc = flat[center]
    g2 = np.zeros(pc.shape)
    for im, ip, lo, hi, hm, hp in zip(minus, plus, at_lo, at_hi, h_minus, h_plus, strict=True):
        pm, pp = flat[im], flat[ip]
        d_minus = np.where(lo, np.minimum(pp - pc, ghost_slope_cap * hp) / hp, (pc - pm) / hm)
        d_plus = np.where(hi, np.maximum(pc - pm, -ghost_slope_cap * hm) / hm, (pp - pc) / hp)
        g2 += np.maximum(np.maximum(d_minus, -d_plus), 0.0) ** 2
    return np.sqrt(g2)


def node_coordinates(cells_xyz: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Node coordinates per axis (z, y, x) from 0, in m, from the cell lengths (x, y, z)."""
    return [np.concatenate([[0.0], np.cumsum(np.asarray(c, dtype=float))]) for c in cells_xyz][::-1]


def around_removed(phi: np.ndarray, coords_zyx: Sequence[np.ndarray], margin: float) -> tuple:
    """Bounding box (slices) of the removed nodes grown by margin (m) plus two nodes per side."""
    neg = phi < 0
    box = []
    for ax, z in enumerate(coords_zyx):
        idx = np.flatnonzero(neg.any(axis=tuple(a for a in range(3) if a != ax)))
        lo = int(np.searchsorted(z, z[idx[0]] - margin, side="left")) - 2
        hi = int(np.searchsorted(z, z[idx[-1]] + margin, side="right")) + 2
        box.append(slice(max(lo, 0), min(hi, z.size)))
    return tuple(box)


def largest_cell(cells_xyz: Sequence[np.ndarray], box: tuple) -> float:
    """The largest cell length (m) of the cells between the nodes of ``box`` (slices z, y, x)."""
    out = 0.0
    for cells, b in zip(tuple(cells_xyz)[::-1], box, strict=True):
        c = np.asarray(cells, dtype=float)
        lo, hi, _ = b.indices(c.size + 1)
        out = max(out, float(c[lo : max(hi - 1, lo + 1)].max()))
    return out


def banded_distance(sub: np.ndarray, coords_zyx: Sequence[np.ndarray], narrow: float) -> np.ndarray:
    """Signed distance (m) to the zero set of ``sub`` on its nodes, NaN beyond ``narrow`` m
    (0: everywhere), as scikit-fmm's narrow band leaves it."""
    x, y, z = coords_zyx[2], coords_zyx[1], coords_zyx[0]
    d = signed_distance(sub, (x, y, z), narrow=narrow)
    if narrow > 0.0:
        d = np.where(np.abs(d) > narrow, np.nan, d)
    return d
