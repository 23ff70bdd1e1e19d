"""Signed distance to the zero set of a nodal field on a rectilinear (graded) grid.

scikit-fmm takes one spacing per axis, so it cannot re-initialise the level set on a graded grid.
This is the fast sweeping method (Zhao 2005) for |grad d| = 1 with per-node spacings:
- start: every node with a sign change to an axis neighbour gets the smaller of two estimates of
  its distance, frozen: the axis intercepts of the zero set by linear interpolation, combined as
  1/d^2 = sum_a 1/d_a^2 (scikit-fmm's start), and |phi| / |grad phi| with second-order
  differences on the graded axes (exact for a plane, where the intercepts are not when one lies
  beyond the neighbour); a node with phi = 0 gets 0; the zero set keeps the sign pattern of phi;
- sweeps: Gauss-Seidel Godunov upwind updates sum_a ((d - a_a)^+ / h_a)^2 = 1, with a_a the
  smaller axis neighbour and h_a the spacing towards it, in the 8 diagonal orders, until nothing
  changes. The nodes of one anti-diagonal plane i + j + k = p never neighbour each other, so a
  whole plane updates at once (vectorised) and the result equals the node-by-node sweep.
First order in h away from the zero set; exact for planes (tested).

Only a band of half-width ``narrow`` wanted (re-initialisation): the same Godunov update of
every node at once (Jacobi), repeated until no node at most ``narrow`` from the zero set
changes. Values only fall, and a node's value depends only on smaller neighbours, so a round in
which no value up to ``narrow`` changed leaves every node of the band at the sweeps' fixed
point (tested against them); nodes beyond it are left above ``narrow``. On the default scene's
crater boxes (5-12 k nodes) it took 17-72 ms where the sweeps' 8 orders x ~70 planes x 2-3
iterations of small plane updates took 0.18-0.46 s.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from diathermy.errors import MeshError, SolverDivergedError


def signed_distance(
    phi: np.ndarray,
    axes_m: Sequence[np.ndarray],
    *,
    max_iterations: int = 30,
    narrow: float = 0.0,
) -> np.ndarray:
    """Signed distance (nz, ny, nx) in m to the zero set of phi (nz, ny, nx), sign of phi kept.

    axes_m: node coordinates (x (nx,), y (ny,), z (nz,)) in m, each strictly increasing.
    narrow > 0: exact (the sweeps' values) only where |d| <= narrow, |d| > narrow elsewhere.
    A field with no zero crossing has no zero set: it is returned unchanged (as a copy).
    """
    phi = np.asarray(phi, dtype=float)
    h = _spacings(phi, axes_m)
    if not np.all(np.isfinite(phi)):
        raise MeshError("signed_distance: phi must be finite")
    d0 = _interface_distance(phi, h)
    if not np.isfinite(d0).any():
        return phi.copy()
    if narrow > 0.0:
        d = _band(d0, np.isfinite(d0), h, narrow)
    else:
        d = _sweep(d0, np.isfinite(d0), h, max_iterations)
    d = np.where((d == 0.0) & (phi != 0.0), np.finfo(float).tiny, d)  # no sign lost to underflow
    return np.where(phi < 0, -d, d)


def _spacings(phi: np.ndarray, axes_m: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Cell lengths per array axis (z (nz-1,), y, x), validated against phi's shape."""
    if phi.ndim != 3 or len(axes_m) != 3:
        raise MeshError("signed_distance: phi must be (nz, ny, nx) with three node axes (x, y, z)")
    out = []
    for n, ax, name in zip(phi.shape, tuple(axes_m)[::-1], "zyx", strict=True):
        a = np.asarray(ax, dtype=float)
        if a.shape != (n,) or n < 2:
            raise MeshError(f"signed_distance: {name} axis must have {n} >= 2 nodes")
        d = np.diff(a)
        if not (np.all(np.isfinite(a)) and np.all(d > 0)):
            raise MeshError(f"signed_distance: {name} node coordinates must increase strictly")
        out.append(d)
    return out


def _interface_distance(phi: np.ndarray, h: list[np.ndarray]) -> np.ndarray:
    """Distance of the nodes beside the zero set (inf elsewhere), from axis-wise interpolation."""
    inv2 = np.zeros(phi.shape)
    zero = phi == 0.0
    for axis, hx in enumerate(h):
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        a, b = phi[tuple(lo)], phi[tuple(hi)]
        cross = (a * b < 0.0) | ((a == 0.0) ^ (b == 0.0))
        shape = [1, 1, 1]
        shape[axis] = -1
        hh = np.broadcast_to(hx.reshape(shape), a.shape)
        with np.errstate(all="ignore"):
            t = np.where(cross, a / (a - b), np.nan)  # crossing at a + t h from the lower node
        d_lo = np.where(cross, t * hh, np.inf)
        d_hi = np.where(cross, (1.0 - t) * hh, np.inf)
        best = np.full(phi.shape, np.inf)
        best[tuple(lo)] = d_lo
        best[tuple(hi)] = np.minimum(best[tuple(hi)], d_hi)
        with np.errstate(all="ignore"):  # extreme phi ratios: 1/d^2 may overflow to inf (d -> 0)
            inv2 += np.where(np.isfinite(best) & (best > 0), 1.0 / best**2, 0.0)
    with np.errstate(all="ignore"):
        d0 = np.where(inv2 > 0, 1.0 / np.sqrt(inv2), np.inf)
        slope = np.sqrt(sum(g**2 for g in _gradient(phi, h)))
        local = np.where(slope > 0, np.abs(phi) / slope, np.inf)
    d0 = np.where(np.isfinite(d0), np.minimum(d0, local), d0)
    d0[zero] = 0.0
    return d0


def _gradient(phi: np.ndarray, h: list[np.ndarray]) -> list[np.ndarray]:
    """d phi / d(z, y, x) on graded axes: 3-point (exact for quadratics) inside, 2-point at ends."""
    out = []
    for axis, hx in enumerate(h):
        f = np.moveaxis(phi, axis, 0)
        g = np.empty_like(f)
        hm = hx[:-1].reshape(-1, 1, 1)
        hp = hx[1:].reshape(-1, 1, 1)
        g[1:-1] = (hm**2 * f[2:] - hp**2 * f[:-2] - (hm**2 - hp**2) * f[1:-1]) / (
            hm * hp * (hm + hp)
        )
        g[0] = (f[1] - f[0]) / hx[0]
        g[-1] = (f[-1] - f[-2]) / hx[-1]
        out.append(np.moveaxis(g, 0, axis))
    return out


def _planes(shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Node indices (3, n) as (k, j, i) ordered by the plane k + j + i, and the plane starts."""
    kji = np.indices(shape).reshape(3, -1)
    p = kji.sum(axis=0)
    order = np.argsort(p, kind="stable")
    starts = np.searchsorted(p[order], np.arange(p.max() + 2))
    return kji[:, order], starts


def _sweep(
    d0: np.ndarray, frozen: np.ndarray, h: list[np.ndarray], max_iterations: int
) -> np.ndarray:
    """Fast sweeping from the frozen start values; the unsigned distance (nz, ny, nx).

    u lives in an inf-padded array so every node has 6 neighbours; the 8 sweep orders visit
    the planes of the index-flipped grid, mapped back to the original indices.
    """
    shape = d0.shape
    U = np.full(tuple(n + 2 for n in shape), np.inf)
    U[1:-1, 1:-1, 1:-1] = d0
    F = np.ones(U.shape, dtype=bool)
    F[1:-1, 1:-1, 1:-1] = frozen
    u, fz = U.ravel(), F.ravel()
    strides = (U.shape[1] * U.shape[2], U.shape[2], 1)
    hpad = [np.concatenate([[1.0], x, [1.0]]) for x in h]  # hpad[i]: to node i-1, [i+1]: to i+1
    nodes, starts = _planes(shape)
    tol = 1e-12 * float(sum(x.sum() for x in h))
    for _ in range(max_iterations):
        changed = False
        for flips in np.ndindex(2, 2, 2):
            kji = [
                (n - 1 - idx) if f else idx for idx, n, f in zip(nodes, shape, flips, strict=True)
            ]
            flat = (kji[0] + 1) * strides[0] + (kji[1] + 1) * strides[1] + kji[2] + 1
            for p in range(starts.size - 1):
                sl = slice(starts[p], starts[p + 1])
                changed |= _update(u, fz, flat[sl], [idx[sl] for idx in kji], strides, hpad, tol)
        if not changed:
            return U[1:-1, 1:-1, 1:-1].copy()
    raise SolverDivergedError(
        f"signed_distance: fast sweeping did not settle in {max_iterations} iterations"
    )


def _band(d0: np.ndarray, frozen: np.ndarray, h: list[np.ndarray], narrow: float) -> np.ndarray:
    """Jacobi rounds of the Godunov update until nothing up to ``narrow`` changes (module doc)."""
    shape = d0.shape
    U = np.full(tuple(n + 2 for n in shape), np.inf)
    U[1:-1, 1:-1, 1:-1] = d0
    u = U.ravel()
    strides = (U.shape[1] * U.shape[2], U.shape[2], 1)
    free = np.indices(shape)[:, ~frozen]  # (3, n_free) as (k, j, i)
    kji = [free[0], free[1], free[2]]
    flat = (kji[0] + 1) * strides[0] + (kji[1] + 1) * strides[1] + kji[2] + 1
    hpad = [np.concatenate([[1.0], x, [1.0]]) for x in h]
    h_lo = [hp[k] for hp, k in zip(hpad, kji, strict=True)]
    h_hi = [hp[k + 1] for hp, k in zip(hpad, kji, strict=True)]
    tol = 1e-12 * float(sum(x.sum() for x in h))
    a = np.empty((flat.size, 3))
    w = np.empty((flat.size, 3))
    for _ in range(sum(shape) * 3 + 3):  # a value moves one node per round
        for axis in range(3):
            ulo, uhi = u[flat - strides[axis]], u[flat + strides[axis]]
            use_lo = ulo <= uhi
            a[:, axis] = np.where(use_lo, ulo, uhi)
            w[:, axis] = np.where(use_lo, h_lo[axis], h_hi[axis])
        cur = u[flat]
        new = np.minimum(cur, godunov_update(a, w))
        u[flat] = new
        if not np.any((new < cur - tol) & (new <= narrow)):
            return U[1:-1, 1:-1, 1:-1].copy()
    raise SolverDivergedError("signed_distance: the band did not settle")


def _update(
    u: np.ndarray,
    frozen: np.ndarray,
    flat: np.ndarray,
    kji: list[np.ndarray],
    strides: tuple[int, int, int],
    hpad: list[np.ndarray],
    tol: float,
) -> bool:
    """Godunov update of the nodes ``flat`` of one plane in place; True if any value dropped."""
    a = np.empty((flat.size, 3))
    w = np.empty((flat.size, 3))
    for axis in range(3):
        ulo, uhi = u[flat - strides[axis]], u[flat + strides[axis]]
        use_lo = ulo <= uhi
        a[:, axis] = np.where(use_lo, ulo, uhi)
        w[:, axis] = np.where(use_lo, hpad[axis][kji[axis]], hpad[axis][kji[axis] + 1])
    cur = u[flat]
    new = np.where(frozen[flat], cur, np.minimum(cur, godunov_update(a, w)))
    u[flat] = new
    return bool(np.any(new < cur - tol))


def godunov_update(a: np.ndarray, h: np.ndarray) -> np.ndarray:
    """The upwind solution d (n,) of sum_a ((d - a_a)^+ / h_a)^2 = 1.

    a: smaller neighbour value per axis (n, 3) (inf where there is none); h: spacing to it (n, 3).
    """
    order = np.argsort(a, axis=1)
    a = np.take_along_axis(a, order, axis=1)
    h = np.take_along_axis(h, order, axis=1)
    d = a[:, 0] + h[:, 0]
    for m in (2, 3):
        sel = np.flatnonzero(d > a[:, m - 1])
        if sel.size == 0:
            break
        aa, ww = a[sel, :m], 1.0 / h[sel, :m] ** 2
        A, B, C = ww.sum(axis=1), (ww * aa).sum(axis=1), (ww * aa**2).sum(axis=1) - 1.0
        d[sel] = (B + np.sqrt(np.maximum(B * B - A * C, 0.0))) / A
    return d
