"""One AMG V-cycle as a preconditioner, without pyamg's residual bookkeeping.

``MultilevelSolver.aspreconditioner`` runs ``solve(b, maxiter=1)``, which also forms the
initial and final residuals and their norms: two extra fine-level mat-vecs per application
(about a quarter of a Chebyshev V-cycle). The cycle below is the same V-cycle without them.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse.linalg as spla
from pyamg.multilevel import MultilevelSolver

SCALAR_AMG_OPTIONS: dict[str, Any] = {
    "presmoother": ("chebyshev", {"degree": 2}),
    "postsmoother": ("chebyshev", {"degree": 2}),
    "improve_candidates": None,
}
"""pyamg smoothed-aggregation options for scalar diffusion (potential, heat at large dt).

Chebyshev smoothing and no candidate improvement: at 64x64x128 the potential takes 16 CG
iterations at 0.67 s against pyamg's default 12 at 2.1 s, and the heat step at dt 1e3 s 18
iterations at 1.1 s against 10 at 1.8 s (benchmarks/results/electrothermal.md).
"""


def v_cycle_preconditioner(ml: MultilevelSolver) -> spla.LinearOperator:
    """x = V-cycle(b) from a zero initial guess; equal to ``ml.aspreconditioner("V")``."""
    levels = ml.levels

    def cycle(lvl: int, b: np.ndarray) -> np.ndarray:
        level = levels[lvl]
        if lvl == len(levels) - 1:
            return np.asarray(ml.coarse_solver(level.A, b)).reshape(b.shape)
        x = np.zeros_like(b)
        level.presmoother(level.A, x, b)
        x += level.P @ cycle(lvl + 1, level.R @ (b - level.A @ x))
        level.postsmoother(level.A, x, b)
        return x

    A = levels[0].A
    return spla.LinearOperator(A.shape, matvec=lambda b: cycle(0, np.ravel(b)), dtype=A.dtype)
