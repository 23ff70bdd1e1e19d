"""Right-preconditioned restarted GMRES with a reusable Krylov basis.

Right preconditioning makes the monitored residual the true residual ||b - A x|| (scipy's
``gmres`` preconditions from the left and stops on the preconditioned residual). Orthogonalisation
is classical Gram-Schmidt applied twice (CGS2): two matrix-vector products with the basis per
iteration instead of one Python-level dot per basis vector, equally stable in practice. The basis
(restart + 1, n) is kept between calls, since fresh large allocations are slow on these machines.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from diathermy.errors import SolverDivergedError

Operator = Callable[[np.ndarray], np.ndarray]


class RightGMRES:
    """Solve A x = b with GMRES(restart) on A M^-1; x = x0 + M^-1 (V y).

    Args:
        name: what is being solved, for error messages.
        restart: Krylov basis size before a restart.
        max_restarts: restart cycles before giving up (raises ``SolverDivergedError``).
    """

    def __init__(self, name: str, *, restart: int = 40, max_restarts: int = 20) -> None:
        self.name = name
        self.restart = restart
        self.max_restarts = max_restarts
        self._basis: np.ndarray | None = None

    def solve(
        self, A: Operator, M: Operator, b: np.ndarray, x0: np.ndarray, rtol: float
    ) -> tuple[np.ndarray, int, float]:
        """x, iterations, final relative residual ||b - A x|| / ||b||."""
        n, m = b.size, self.restart
        if self._basis is None or self._basis.shape != (m + 1, n):
            self._basis = np.empty((m + 1, n))
        V = self._basis
        b_norm = float(np.linalg.norm(b))
        if b_norm == 0.0:
            return np.zeros_like(b), 0, 0.0
        x = x0.astype(float, copy=True)
        its = 0
        for _ in range(self.max_restarts):
            r = b - A(x)
            beta = float(np.linalg.norm(r))
            if beta <= rtol * b_norm:
                return x, its, beta / b_norm
            V[0] = r / beta
            H = np.zeros((m + 1, m))
            k = 0
            for k in range(m):
                w = A(M(V[k]))
                for _pass in range(2):  # CGS2
                    h = V[: k + 1] @ w
                    w -= h @ V[: k + 1]
                    H[: k + 1, k] += h
                H[k + 1, k] = np.linalg.norm(w)
                its += 1
                e1 = np.zeros(k + 2)
                e1[0] = beta
                y, *_ = np.linalg.lstsq(H[: k + 2, : k + 1], e1, rcond=None)
                res = float(np.linalg.norm(e1 - H[: k + 2, : k + 1] @ y))
                if H[k + 1, k] <= 1e-14 * beta or res <= rtol * b_norm:
                    break
                V[k + 1] = w / H[k + 1, k]
            x += M(y @ V[: k + 1])
        r_norm = float(np.linalg.norm(b - A(x)))
        if r_norm <= rtol * b_norm * 1.01:
            return x, its, r_norm / b_norm
        raise SolverDivergedError(
            f"{self.name}: GMRES did not converge (relative residual {r_norm / b_norm:.3e} > "
            f"{rtol:.1e} after {its} iterations)",
            iterations=its,
            residual=r_norm / b_norm,
        )
