"""Non-local average of a nodal field over a material length, for the dissection driver.

The local law F = v0 max(0, W / kappa - 1) reads the strain energy at a node, and W peaks on the
crater floor under the contact, a peak that sharpens as the cells shrink: the crater then grows
with the resolution instead of converging (docs/resolution.md). Integral (non-local) damage
models regularise exactly this (Pijaudier-Cabot and Bazant 1987): the driver is the weighted mean
of W over a neighbourhood of the point,

    W_bar(x) = int w(|x - y|) W(y) chi(y) dy / int w(|x - y|) chi(y) dy,

w the Gaussian of standard deviation l (per axis, lowered to reach zero at ``TRUNCATE`` l,
so that it is continuous and the nodal quadrature stays second order) and chi the healthy tissue, so that cut
tissue neither dilutes nor feeds the mean. l is a tissue property (the scene's
``level_set.nonlocal_length_m``); l -> 0 is the local law, and once the cells are well below l
the driver, and with it the crater, stops depending on the grid.

On the structured (graded) tensor grid the Gaussian factorises per axis, so the 3-D integral is
three banded 1-D products over the node coordinates, with the lumped nodal volumes of the healthy
tets as quadrature weights: O(n_nodes x band) per call, no neighbour search.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp

TRUNCATE = 3.0
"""The kernel reaches zero at this many lengths l (the Gaussian there is 1.1 % of its centre)."""


def kernel_weight(s_m: np.ndarray, length_m: float) -> np.ndarray:
    """The 1-D kernel at offsets s (m): exp(-s^2 / (2 l^2)) - exp(-T^2 / 2) within T l, else 0."""
    s = np.asarray(s_m, dtype=float) / length_m
    w = np.exp(-0.5 * s**2) - np.exp(-0.5 * TRUNCATE**2)
    return np.where(np.abs(s) < TRUNCATE, w, 0.0)


def axis_kernel(coords_m: np.ndarray, length_m: float) -> sp.csr_matrix:
    """``kernel_weight`` between the nodes (n,) of one axis (m), a sparse symmetric (n, n)."""
    x = np.asarray(coords_m, dtype=float)
    reach = TRUNCATE * length_m * (1.0 + 1e-9)  # candidates; the weight itself cuts off exactly
    lo = np.searchsorted(x, x - reach, side="left")
    hi = np.searchsorted(x, x + reach, side="right")
    rows = np.repeat(np.arange(x.size), hi - lo)
    cols = np.concatenate([np.arange(a, b) for a, b in zip(lo, hi, strict=True)])
    w = kernel_weight(x[rows] - x[cols], length_m)  # x_i - x_j = -(x_j - x_i): symmetric
    keep = w > 0.0
    return sp.csr_matrix((w[keep], (rows[keep], cols[keep])), shape=(x.size, x.size))


def axis_kernels(axes_xyz: Sequence[np.ndarray], length_m: float) -> tuple[sp.csr_matrix, ...]:
    """The three axis kernels in array order (z, y, x) for node coordinates (x, y, z) in m."""
    if not (np.isfinite(length_m) and length_m > 0.0):
        raise ValueError(f"non-local length must be a positive length in m, got {length_m}")
    return tuple(axis_kernel(a, length_m) for a in (axes_xyz[2], axes_xyz[1], axes_xyz[0]))


def _smooth(field: np.ndarray, kernels_zyx: Sequence[sp.csr_matrix]) -> np.ndarray:
    """Apply the separable kernel to a (nz, ny, nx) array: one banded product per axis."""
    out = field
    for axis, k in enumerate(kernels_zyx):
        moved = np.moveaxis(out, axis, 0)
        flat = k @ moved.reshape(moved.shape[0], -1)
        out = np.moveaxis(flat.reshape(moved.shape), 0, axis)
    return out


def nonlocal_mean(
    values: np.ndarray,
    weights: np.ndarray,
    shape: tuple[int, int, int],
    kernels_zyx: Sequence[sp.csr_matrix],
) -> np.ndarray:
    """Weighted Gaussian mean (n_nodes,) of a nodal field over the kernel's neighbourhood.

    Args:
        values: the nodal field (n_nodes,), e.g. W in J/m^3.
        weights: quadrature weight per node (n_nodes,), e.g. its lumped healthy volume in m^3;
            nodes with zero weight do not count, but get the mean of their neighbourhood (0
            where no weighted node is within reach).
        shape: the grid's (nz, ny, nx).
        kernels_zyx: ``axis_kernels`` of the grid.
    """
    w = np.asarray(weights, dtype=float).reshape(shape)
    num = _smooth(w * np.asarray(values, dtype=float).reshape(shape), kernels_zyx)
    den = _smooth(w, kernels_zyx)
    floor = 1e-12 * float(den.max()) if den.size else 0.0
    out = np.where(den > floor, num / np.where(den > floor, den, 1.0), 0.0)
    return out.ravel()
