"""Preconditioned CG stopped by an estimate of the energy-norm error, not by the residual.

For SPD A and an SPD preconditioner M ~ A^-1, the error e = x* - x of an iterate satisfies
||e||_A^2 = r^T A^-1 r with r = b - A x, so sqrt(r^T M r) / ||x||_A estimates the relative
energy-norm error; both quantities come free with PCG (r^T z, and x^T A x = x^T (b - r)). On
a fine graded mesh the plain residual ||r|| / ||b|| does not bound the error (the smooth,
far-field part of the error leaves almost no residual), the preconditioned one does as far as
the V-cycle is a good inverse. It reads low where M is a weak inverse: with the degree-3 V-cycle
it read 0.5-0.9x the true relative energy error on a default-grid cutting step; with the
degree-1 V-cycle the mechanics uses now, 0.22-0.52x (median 0.31-0.39) on every cutting step of
the three built-in graded grids (benchmarks/results/guard_estimate.md), so a tolerance on it
admits 2-4x that true error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


@dataclass(frozen=True)
class EnergyCG:
    """An iterate x, the PCG iterations it took, its relative energy-error estimate
    sqrt(r.M r) / sqrt(x.A x) and its relative residual ||b - A x|| / ||b||."""

    x: np.ndarray
    iterations: int
    estimate: float
    residual: float


def energy_cg(
    A: sp.spmatrix | spla.LinearOperator,
    b: np.ndarray,
    x0: np.ndarray,
    M: spla.LinearOperator,
    *,
    tol: float,
    maxiter: int,
    norm_sq: float | None = None,
    residual: np.ndarray | None = None,
) -> EnergyCG:
    """PCG on A x = b from x0 until the energy-error estimate is at most ``tol`` or after
    ``maxiter`` iterations (0: only the estimate of x0, one V-cycle).

    ``norm_sq``: the squared energy norm the estimate is relative to (default the iterate's own
    x.A x; a correction solved for on its own passes the norm of the whole answer).
    ``residual``: b - A x0 when the caller has it (saves a mat-vec)."""
    if not 0 < tol < 1 or maxiter < 0:
        raise ValueError(f"tol must lie in (0, 1) and maxiter be >= 0, got {tol}, {maxiter}")
    b_norm = float(np.linalg.norm(b))
    x = np.array(x0, dtype=float)
    r = b - A @ x if residual is None else np.array(residual, dtype=float)
    z = M @ r
    rz = float(r @ z)
    p = z.copy()
    its = 0
    while True:
        xAx = float(x @ (b - r)) if norm_sq is None else norm_sq
        estimate = np.sqrt(max(rz, 0.0) / xAx) if xAx > 0 else np.inf
        if estimate <= tol or its >= maxiter or rz <= 0:
            break
        Ap = A @ p
        pAp = float(p @ Ap)
        if not pAp > 0:
            break
        alpha = rz / pAp
        x += alpha * p
        r -= alpha * Ap
        z = M @ r
        rz, rz_old = float(r @ z), rz
        p *= rz / rz_old
        p += z
        its += 1
    relative = float(np.linalg.norm(r)) / b_norm if b_norm > 0 else 0.0
    return EnergyCG(x, its, float(estimate), relative)
