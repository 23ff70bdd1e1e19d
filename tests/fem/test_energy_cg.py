"""PCG stopped by the energy-error estimate (fem.energy_cg): the estimate tracks the true
energy-norm error, the tolerance is met, and bad arguments are refused."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from diathermy.fem.energy_cg import energy_cg
from diathermy.fem.multigrid import scaled_amg_preconditioner


def _poisson(n: int) -> sp.csr_matrix:
    """3D 7-point Laplacian (Dirichlet) on n^3 nodes, SPD."""
    one = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    eye = sp.identity(n)
    return (
        sp.kron(sp.kron(one, eye), eye) + sp.kron(sp.kron(eye, one), eye)
        + sp.kron(sp.kron(eye, eye), one)
    ).tocsr()  # fmt: skip


@pytest.fixture(scope="module")
def system() -> tuple[sp.csr_matrix, np.ndarray, np.ndarray, spla.LinearOperator]:
    A = _poisson(20)
    rng = np.random.default_rng(3)
    x_true = rng.standard_normal(A.shape[0])
    return A, A @ x_true, x_true, scaled_amg_preconditioner(A)


def _energy_error(A: sp.csr_matrix, x: np.ndarray, x_true: np.ndarray) -> float:
    e = x - x_true
    return float(np.sqrt(e @ (A @ e) / (x_true @ (A @ x_true))))


@pytest.mark.parametrize("tol", [1e-2, 1e-3, 1e-5])
def test_reaches_the_tolerance_and_the_estimate_tracks_the_error(system, tol):
    A, b, x_true, M = system
    start = 0.9 * x_true + 0.05 * np.roll(x_true, 7)  # a perturbed previous answer
    res = energy_cg(A, b, start, M, tol=tol, maxiter=200)
    assert res.estimate <= tol
    true = _energy_error(A, res.x, x_true)
    assert 0.2 * true <= res.estimate <= 5.0 * true  # a V-cycle is a good inverse here
    assert res.iterations > 0
    assert res.residual == pytest.approx(np.linalg.norm(b - A @ res.x) / np.linalg.norm(b))


def test_more_iterations_never_raise_the_energy_error(system):
    A, b, x_true, M = system
    errors = [
        _energy_error(A, energy_cg(A, b, np.zeros_like(b), M, tol=1e-12, maxiter=k).x, x_true)
        for k in range(6)
    ]
    assert all(e2 <= e1 * (1 + 1e-12) for e1, e2 in zip(errors, errors[1:], strict=False))


def test_zero_iterations_only_estimates(system):
    A, b, x_true, M = system
    res = energy_cg(A, b, x_true, M, tol=0.5, maxiter=0)
    assert res.iterations == 0 and np.array_equal(res.x, x_true) and res.estimate < 1e-8


@pytest.mark.parametrize("tol, maxiter", [(0.0, 5), (1.0, 5), (1e-3, -1)])
def test_bad_arguments(system, tol, maxiter):
    A, b, x_true, M = system
    with pytest.raises(ValueError, match="tol"):
        energy_cg(A, b, x_true, M, tol=tol, maxiter=maxiter)
