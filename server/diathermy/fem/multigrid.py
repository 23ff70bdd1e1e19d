"""AMG for scalar diffusion: options, unit-diagonal scaling and a lean V-cycle preconditioner.

Chebyshev smoothing (cheap per sweep, see ``SCALAR_AMG_OPTIONS``) is a polynomial in A itself,
so it needs A's diagonal to be even: a cut (sigma 1e-5 beside 0.33) made it take 88 CG
iterations at 64x64x128. Build hierarchies on the unit-diagonal scaling D^-1/2 A D^-1/2
(``unit_diagonal``) with the scaled constant 1/d = D^1/2 1 as near-nullspace candidate
(``scaled_candidates``): 16 iterations with the cut and without it, as unscaled without it.

``MultilevelSolver.aspreconditioner`` runs ``solve(b, maxiter=1)``, which also forms the
initial and final residuals and their norms: two extra fine-level mat-vecs per application
(about a quarter of a Chebyshev V-cycle). ``v_cycle_preconditioner`` is the same V-cycle without.

pyamg's default coarse solver, 'pinv', forms a pseudo-inverse by SVD on its first call: ~16 ms
for the elasticity hierarchy's 234 coarsest rows on one BLAS thread (up to 140 ms with a
threaded OpenBLAS on 2 busy cores), paid again whenever a cut refreshes the coarse operators
(``galerkin_refresh``), every cutting step. ``coarse_solver("cholesky")`` factors instead
(0.35 ms) and falls back to the pseudo-inverse only where the coarsest operator is not
numerically positive definite.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np
import pyamg
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from pyamg.multilevel import MultilevelSolver, coarse_grid_solver
from threadpoolctl import ThreadpoolController

SCALAR_AMG_OPTIONS: dict[str, Any] = {
    "presmoother": ("chebyshev", {"degree": 2}),
    "postsmoother": ("chebyshev", {"degree": 2}),
    "improve_candidates": None,
}
"""pyamg smoothed-aggregation options for scalar diffusion (potential, heat at large dt).

Chebyshev smoothing and no candidate improvement: at 64x64x128 the potential takes 16 CG
iterations against pyamg's default 12, in 2-3x less time (three runs side by side), and the
heat step at dt 1e3 s 18 iterations against 10 in 1.6x less (benchmarks/results/electrothermal.md).
"""


def unit_diagonal(A: sp.csr_matrix) -> tuple[sp.csr_matrix, np.ndarray]:
    """(D^-1/2 A D^-1/2, d = diag(A)^-1/2) for an SPD CSR matrix A; x = d * y solves A x = b
    where y solves the scaled system with right-hand side d * b."""
    diag = A.diagonal()
    if np.any(diag <= 0):
        raise ValueError("unit_diagonal needs a positive diagonal")
    d = 1.0 / np.sqrt(diag)
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    data = A.data * d[rows] * d[A.indices]
    return sp.csr_matrix((data, A.indices, A.indptr), shape=A.shape), d


def scaled_candidates(d: np.ndarray) -> np.ndarray:
    """Near-nullspace (n, 1) of the scaled matrix: the constant of A seen through D^1/2."""
    return (1.0 / d)[:, None]


@cache
def _blas_pools() -> ThreadpoolController:
    """The process's BLAS pools, looked up once (scipy.linalg's OpenBLAS is loaded by now)."""
    return ThreadpoolController()


class CholeskyCoarseSolver:
    """The coarsest level's exact solve: a Cholesky factor of the dense operator, formed on the
    first call (pyamg's coarse-solver protocol, ``solver(A, b)``; one instance per operator); a
    pseudo-inverse instead when the operator is not numerically positive definite (the
    factorization fails, or a pivot is below n eps times the largest: a singular operator). The
    factorization runs on one BLAS thread whatever the process set: on a busy 2-core machine a
    threaded OpenBLAS took 35-116 ms for what one thread does in 0.5 ms."""

    def __init__(self) -> None:
        self._factor: tuple[np.ndarray, bool] | None = None
        self._pinv: np.ndarray | None = None

    @property
    def fell_back(self) -> bool:
        """Whether the operator needed the pseudo-inverse."""
        return self._pinv is not None

    def __call__(self, A: Any, b: np.ndarray) -> np.ndarray:
        b = np.asarray(b)
        if self._factor is None and self._pinv is None:
            dense = A.toarray() if sp.issparse(A) else np.asarray(A)
            try:
                with _blas_pools().limit(limits=1, user_api="blas"):
                    factor = sla.cho_factor(dense, lower=True, check_finite=False)
                pivots = np.diag(factor[0]) ** 2
                # a singular operator can factor to a rounding-sized pivot: no better than none
                if pivots.min() <= dense.shape[0] * np.finfo(float).eps * pivots.max():
                    raise np.linalg.LinAlgError("numerically singular")
                self._factor = factor
            except np.linalg.LinAlgError:
                with _blas_pools().limit(limits=1, user_api="blas"):
                    self._pinv = sla.pinv(dense)
        if self._pinv is not None:
            return (self._pinv @ b.reshape(self._pinv.shape[1], -1)).reshape(b.shape)
        assert self._factor is not None
        x = sla.cho_solve(self._factor, b.reshape(self._factor[0].shape[0], -1), check_finite=False)
        return np.asarray(x).reshape(b.shape)

    def __repr__(self) -> str:
        return "coarse_solver('cholesky')"


def coarse_solver(name: str) -> Any:
    """A fresh coarse solver for a hierarchy's coarsest operator: ours for 'cholesky' (see the
    module docstring), pyamg's ``coarse_grid_solver(name)`` for any other name."""
    return CholeskyCoarseSolver() if name == "cholesky" else coarse_grid_solver(name)


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


def scaled_amg_preconditioner(A: sp.csr_matrix) -> spla.LinearOperator:
    """One V-cycle for A, built on its unit-diagonal scaling: r -> d * V(d * r)."""
    As, d = unit_diagonal(A)
    ml = deterministic_sa(As, scaled_candidates(d), SCALAR_AMG_OPTIONS)
    V = v_cycle_preconditioner(ml)
    return spla.LinearOperator(A.shape, matvec=lambda r: d * (V @ (d * np.ravel(r))), dtype=float)


def deterministic_sa(A: sp.spmatrix, B: np.ndarray | None, options: dict[str, Any]) -> Any:
    """pyamg smoothed aggregation with its random spectral-radius start vectors seeded.

    pyamg draws those vectors from numpy's global generator; seeding it (and putting the caller's
    state back) makes the hierarchy a function of the matrix alone, so equal operators give equal
    iterates and a restored checkpoint repeats the original run bit for bit. pyamg also caches
    spectral radii on the matrix (``A.rho``, ``A.rho_D_inv``) from earlier setups and cycles; it is dropped first.
    """
    for cached in ("rho", "rho_D_inv", "rho_block_D_inv"):  # pyamg's caches on the matrix
        if hasattr(A, cached):
            delattr(A, cached)
    name = options.get("coarse_solver", "pinv")
    saved = np.random.get_state()  # noqa: NPY002 (pyamg draws from the legacy global state)
    np.random.seed(20260101)  # noqa: NPY002
    try:
        # pyamg knows 'cholesky' too, without the fallback: ours replaces it below
        ml = pyamg.smoothed_aggregation_solver(A, B=B, **options)
    finally:
        np.random.set_state(saved)  # noqa: NPY002
    if name == "cholesky":
        ml.coarse_solver = coarse_solver(name)
    return ml
