"""The lean V-cycle is pyamg's V-cycle minus the bookkeeping; scaling keeps AMG robust."""

from __future__ import annotations

import numpy as np
import pyamg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from diathermy.fem.multigrid import (
    CholeskyCoarseSolver,
    coarse_solver,
    deterministic_sa,
    scaled_amg_preconditioner,
    unit_diagonal,
    v_cycle_preconditioner,
)


def test_v_cycle_equals_pyamg_preconditioner(rng):
    A = pyamg.gallery.poisson((16, 16, 16), format="csr")
    for options in (
        {},
        {"presmoother": ("chebyshev", {"degree": 2}), "postsmoother": ("chebyshev", {"degree": 2})},
    ):
        ml = pyamg.smoothed_aggregation_solver(A, max_coarse=20, **options)
        assert len(ml.levels) >= 3
        b = rng.normal(size=A.shape[0])
        ref = ml.aspreconditioner(cycle="V") @ b
        assert np.allclose(
            v_cycle_preconditioner(ml) @ b, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max()
        )


def test_unit_diagonal_scaling(rng):
    A = pyamg.gallery.poisson((6, 7), format="csr")
    A = (A + sp.diags(rng.uniform(0, 5, A.shape[0]))).tocsr()
    As, d = unit_diagonal(A)
    assert np.allclose(As.diagonal(), 1.0)
    assert np.allclose(As.toarray(), np.diag(d) @ A.toarray() @ np.diag(d))


def test_scaled_amg_preconditions_a_high_contrast_problem(rng):
    """sigma 1e-5 in a block of a 3-D Poisson problem: CG with the scaled V-cycle converges."""
    n = 14
    A = pyamg.gallery.poisson((n, n, n), format="csr")
    w = np.where(rng.uniform(size=A.shape[0]) < 0.1, 1e-5, 1.0)
    W = sp.diags(np.sqrt(w))
    A = (W @ A @ W + sp.diags(1e-3 * w)).tocsr()  # SPD with a 1e5 contrast
    b = rng.normal(size=A.shape[0])
    its = [0]
    x, info = spla.cg(
        A, b, rtol=1e-8, M=scaled_amg_preconditioner(A), maxiter=200,
        callback=lambda _: its.__setitem__(0, its[0] + 1),
    )  # fmt: skip
    assert info == 0 and its[0] < 60
    assert np.linalg.norm(b - A @ x) <= 1e-8 * np.linalg.norm(b) * 1.01


def test_cholesky_coarse_solver_solves_an_spd_operator_exactly(rng):
    A = pyamg.gallery.poisson((7, 8), format="bsr") + sp.eye(56, format="bsr")
    solve = CholeskyCoarseSolver()
    b = rng.normal(size=56)
    x = solve(A, b)
    assert not solve.fell_back and x.shape == b.shape
    assert np.linalg.norm(A @ x - b) <= 1e-12 * np.linalg.norm(b)
    B = rng.normal(size=(56, 3))  # several right-hand sides, as pyamg may pass
    assert np.allclose(solve(A, B), np.linalg.solve(A.toarray(), B), rtol=1e-10, atol=1e-12)


def test_cholesky_coarse_solver_falls_back_to_the_pseudo_inverse_when_singular(rng):
    """A pure-Neumann Laplacian (constants in its null space) is not positive definite: the
    least-norm solution of the pseudo-inverse, as pyamg's default gives."""
    A = pyamg.gallery.poisson((6, 6), format="csr").tolil()
    A.setdiag(0)
    A.setdiag(-np.asarray(A.sum(axis=1)).ravel())
    A = A.tocsr()
    b = rng.normal(size=36)
    b -= b.mean()  # in the range
    solve = CholeskyCoarseSolver()
    x = solve(A, b)
    assert solve.fell_back
    assert np.allclose(x, np.linalg.pinv(A.toarray()) @ b, rtol=1e-9, atol=1e-12)
    assert np.linalg.norm(A @ x - b) <= 1e-9 * np.linalg.norm(b)


def test_cholesky_hierarchy_cycles_as_the_pseudo_inverse_one(rng):
    """'cholesky' changes how the coarsest SPD system is solved, not its answer: the same V-cycle
    as pyamg's 'pinv' to rounding; other names stay pyamg's own."""
    A = pyamg.gallery.poisson((12, 12, 12), format="csr")
    opts = {"max_coarse": 40}
    ml_c = deterministic_sa(A, None, {**opts, "coarse_solver": "cholesky"})
    ml_p = deterministic_sa(A, None, {**opts, "coarse_solver": "pinv"})
    assert isinstance(ml_c.coarse_solver, CholeskyCoarseSolver)
    assert not isinstance(coarse_solver("pinv"), CholeskyCoarseSolver)
    b = rng.normal(size=A.shape[0])
    ref = v_cycle_preconditioner(ml_p) @ b
    got = v_cycle_preconditioner(ml_c) @ b
    assert np.linalg.norm(got - ref) <= 1e-10 * np.linalg.norm(ref)


def test_the_coarse_factor_runs_on_one_blas_thread_whatever_the_process_set(
    rng, monkeypatch
) -> None:
    """A threaded OpenBLAS took 35-116 ms for a 0.5 ms factor on a busy 2-core machine: the
    factorization limits itself, even where the caller allowed more threads."""
    import scipy.linalg as sla
    from threadpoolctl import threadpool_info, threadpool_limits

    import diathermy.fem.multigrid as mg

    seen: list[int] = []
    factor = sla.cho_factor

    def spy(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        seen.extend(p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas")
        return factor(*args, **kwargs)

    monkeypatch.setattr(mg.sla, "cho_factor", spy)
    A = pyamg.gallery.poisson((6, 6), format="csr") + sp.eye(36, format="csr")
    with threadpool_limits(limits=2, user_api="blas"):
        CholeskyCoarseSolver()(A, rng.normal(size=36))
    assert seen and set(seen) == {1}
