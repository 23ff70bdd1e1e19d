"""The lean V-cycle is pyamg's V-cycle minus the bookkeeping; scaling keeps AMG robust."""

from __future__ import annotations

import numpy as np
import pyamg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from diathermy.fem.multigrid import scaled_amg_preconditioner, unit_diagonal, v_cycle_preconditioner


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
