"""Krylov solvers with algebraic-multigrid preconditioning that reuse their setup across steps.

A solver object is data (the operator, its preconditioner and counters) plus ``solve``. The AMG
hierarchy (pyamg smoothed aggregation) is rebuilt only when the caller says the operator changed,
and even then it may be kept as a preconditioner for the new operator while the iteration count
stays close to that of a fresh hierarchy (``stale_factor``). Every solve checks the true residual
and raises ``SolverDivergedError`` rather than return an unconverged field.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from diathermy.errors import SolverDivergedError
from diathermy.fem.multigrid import deterministic_sa, v_cycle_preconditioner

Preconditioner = Literal["amg", "jacobi", "none"]


@dataclass(frozen=True)
class SolveStats:
    """What one linear solve did: iterations, final relative residual, time in s."""

    iterations: int
    residual: float
    setup_s: float
    solve_s: float
    rebuilt: bool


class KrylovSolver:
    """Preconditioned CG (or GMRES for nonsymmetric operators) with setup reuse and warm starts.

    Args:
        name: what is being solved, for error messages ("potential", "elasticity").
        rtol: relative residual ||b - A x|| / ||b|| to reach.
        maxiter: iteration cap; reaching it without convergence raises.
        preconditioner: "amg" (pyamg smoothed aggregation), "jacobi" or "none".
        near_nullspace: (n, k) near-nullspace candidates for AMG (rigid-body modes for elasticity).
        amg_options: extra keyword arguments to ``pyamg.smoothed_aggregation_solver``.
        stale_factor: keep an outdated hierarchy while iterations <= stale_factor x the
            iterations of the last fresh one; 0 rebuilds on every operator change.
        method: "cg" for SPD operators, "gmres" otherwise.
    """

    def __init__(
        self,
        name: str,
        *,
        rtol: float = 1e-8,
        maxiter: int = 1000,
        preconditioner: Preconditioner = "amg",
        near_nullspace: np.ndarray | None = None,
        amg_options: dict[str, Any] | None = None,
        stale_factor: float = 0.0,
        method: Literal["cg", "gmres"] = "cg",
    ) -> None:
        if not 0 < rtol < 1:
            raise ValueError(f"{name}: rtol must lie in (0, 1), got {rtol}")
        self.name = name
        self.rtol = rtol
        self.maxiter = maxiter
        self.preconditioner = preconditioner
        self.near_nullspace = near_nullspace
        self.amg_options = dict(amg_options or {})
        self.stale_factor = stale_factor
        self.method = method
        self.A: sp.spmatrix | None = None
        self._M: spla.LinearOperator | None = None
        self._fresh_iterations: int | None = None
        self._stale = False
        self._last_x: np.ndarray | None = None
        self.n_setups = 0
        self.n_solves = 0

    @property
    def hierarchy_levels(self) -> int:
        ml = getattr(self, "_ml", None)
        return len(ml.levels) if ml is not None else 0

    @property
    def warm_start(self) -> np.ndarray | None:
        """The last solution, the next solve's initial guess (None: start from zero)."""
        return self._last_x

    @warm_start.setter
    def warm_start(self, x: np.ndarray | None) -> None:
        self._last_x = None if x is None else np.asarray(x, dtype=float).copy()

    def set_operator(self, A: sp.spmatrix) -> None:
        """Give the solver a new operator; its preconditioner is rebuilt now or on staleness."""
        if self.A is not None and A.shape != self.A.shape:
            self._M = None
            self._last_x = None
        self.A = A
        if self._M is not None and self.stale_factor > 0:
            self._stale = True
        else:
            self._M = None

    def _setup(self) -> float:
        assert self.A is not None
        t0 = time.perf_counter()
        A = self.A
        if self.preconditioner == "amg":
            self._ml = deterministic_sa(A, self.near_nullspace, self.amg_options)
            self._M = v_cycle_preconditioner(self._ml)
        elif self.preconditioner == "jacobi":
            d = A.diagonal()
            if np.any(d <= 0):
                raise SolverDivergedError(f"{self.name}: Jacobi needs a positive diagonal")
            inv = 1.0 / d
            self._M = spla.LinearOperator(A.shape, matvec=lambda r: inv * r, dtype=float)
        else:
            self._M = spla.LinearOperator(A.shape, matvec=lambda r: r, dtype=float)
        self._stale = False
        self.n_setups += 1
        return time.perf_counter() - t0

    def solve(self, b: np.ndarray, x0: np.ndarray | None = None) -> tuple[np.ndarray, SolveStats]:
        """Solve A x = b from x0 (default: the previous solution, a warm start)."""
        if self.A is None:
            raise SolverDivergedError(f"{self.name}: no operator set")
        if not np.all(np.isfinite(b)):
            raise SolverDivergedError(f"{self.name}: right-hand side is not finite")
        b_norm = float(np.linalg.norm(b))
        if b_norm == 0.0:
            return np.zeros_like(b), SolveStats(0, 0.0, 0.0, 0.0, False)
        if x0 is None and self._last_x is not None and self._last_x.shape == b.shape:
            x0 = self._last_x
        rebuilt = self._M is None
        setup_s = self._setup() if rebuilt else 0.0
        x, its, t_solve = self._krylov(b, x0)
        res = float(np.linalg.norm(b - self.A @ x)) / b_norm
        if self._stale and (
            res > self.rtol or its > self.stale_factor * max(self._fresh_iterations or 1, 1)
        ):
            setup_s += self._setup()  # the old hierarchy no longer pays: rebuild and redo
            rebuilt = True
            x, its2, t2 = self._krylov(b, x)
            its += its2
            t_solve += t2
            res = float(np.linalg.norm(b - self.A @ x)) / b_norm
        if rebuilt:
            self._fresh_iterations = its
        self.n_solves += 1
        if not np.isfinite(res) or res > self.rtol * 1.01:
            raise SolverDivergedError(
                f"{self.name}: Krylov solve did not converge (relative residual {res:.3e} > "
                f"{self.rtol:.1e} after {its} iterations)",
                iterations=its,
                residual=res,
            )
        self._last_x = x
        return x, SolveStats(its, res, setup_s, t_solve, rebuilt)

    def _krylov(self, b: np.ndarray, x0: np.ndarray | None) -> tuple[np.ndarray, int, float]:
        count = [0]

        def tick(_: Any) -> None:
            count[0] += 1

        t0 = time.perf_counter()
        if self.method == "cg":
            x, _ = spla.cg(
                self.A,
                b,
                x0=x0,
                rtol=self.rtol,
                atol=0.0,
                maxiter=self.maxiter,
                M=self._M,
                callback=tick,
            )
        else:
            x, _ = spla.gmres(
                self.A, b, x0=x0, rtol=self.rtol, atol=0.0, restart=50, maxiter=self.maxiter,
                M=self._M, callback=tick, callback_type="pr_norm",
            )  # fmt: skip
        return x, count[0], time.perf_counter() - t0
