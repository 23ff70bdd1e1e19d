"""Right-preconditioned GMRES solves nonsymmetric systems and refuses to return garbage."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from diathermy.errors import SolverDivergedError
from diathermy.fem.gmres import RightGMRES


def convection_diffusion(n: int) -> sp.csr_matrix:
    """1-D upwinded convection-diffusion: nonsymmetric, diagonally dominant."""
    main, lower, upper = 2.5 * np.ones(n), -1.4 * np.ones(n - 1), -0.6 * np.ones(n - 1)
    return sp.diags([lower, main, upper], [-1, 0, 1], format="csr")


def test_matches_direct_solve_with_restarts(rng):
    A = convection_diffusion(400)
    b = rng.normal(size=400)
    inv_diag = 1.0 / A.diagonal()
    solver = RightGMRES("test", restart=10, max_restarts=50)
    x, its, res = solver.solve(lambda v: A @ v, lambda r: inv_diag * r, b, np.zeros(400), 1e-10)
    assert res <= 1e-10 and its > 10  # it restarted
    assert np.allclose(x, spla.spsolve(A.tocsc(), b), rtol=1e-8, atol=1e-8)
    # a second solve reuses the basis and starts from a good guess
    x2, its2, _ = solver.solve(lambda v: A @ v, lambda r: inv_diag * r, b, x, 1e-10)
    assert its2 == 0 and np.array_equal(x2, x)


def test_raises_when_it_cannot_converge(rng):
    A = convection_diffusion(400)
    solver = RightGMRES("test", restart=2, max_restarts=1)
    with pytest.raises(SolverDivergedError, match="test: GMRES did not converge"):
        solver.solve(lambda v: A @ v, lambda r: r, rng.normal(size=400), np.zeros(400), 1e-12)
