"""A kept AMG hierarchy preconditions a changed operator: CG still solves the *new* system to its
tolerance, the Ritz-scaled warm start is never worse than the raw one, and a hierarchy that no
longer pays (or has served its interval) is rebuilt."""

from __future__ import annotations

import numpy as np
import pyamg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from diathermy.fem.multigrid import SCALAR_AMG_OPTIONS
from diathermy.fem.solvers import KrylovSolver, convergence_rate

N = 14


def diffusion(weights: np.ndarray) -> sp.csr_matrix:
    """7-point diffusion on an N^3 grid with per-node weights (a conductivity), SPD."""
    A = pyamg.gallery.poisson((N, N, N), format="csr")
    W = sp.diags(np.sqrt(weights))
    return (W @ A @ W + sp.diags(1e-3 * weights)).tocsr()


def solver(**kw: float) -> KrylovSolver:
    return KrylovSolver("test", rtol=1e-9, amg_options=SCALAR_AMG_OPTIONS, **kw)


def relative_residual(A: sp.spmatrix, x: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(b - A @ x) / np.linalg.norm(b))


def test_kept_hierarchy_solves_the_new_system(rng):
    """A local change (a cut: 1e-5 on a few nodes) keeps the hierarchy; the answer is the fresh
    direct solve's within what rtol allows, and the residual is the new operator's."""
    w = np.ones(N**3)
    s = solver(stale_factor=2.0)
    s.set_operator(diffusion(w))
    b = rng.normal(size=N**3)
    _, first = s.solve(b)
    assert first.rebuilt and not first.stale
    w[rng.choice(N**3, 20, replace=False)] = 1e-5
    A2 = diffusion(w)
    s.set_operator(A2)
    x, st = s.solve(b, np.zeros_like(b))
    assert st.stale and not st.rebuilt and s.n_setups == 1
    assert relative_residual(A2, x, b) <= 1e-9 * 1.01
    exact = spla.spsolve(A2.tocsc(), b)
    # ||x - x*|| <= cond(A2) ||r|| / ||A2||: the residual bound of the tolerance, measured
    assert np.linalg.norm(x - exact) <= 1e-5 * np.linalg.norm(exact)
    fresh = solver()
    fresh.set_operator(A2)
    x_fresh, st_fresh = fresh.solve(b)
    assert st_fresh.rebuilt
    assert np.linalg.norm(x - x_fresh) <= 1e-5 * np.linalg.norm(exact)


def test_hierarchy_that_stops_paying_is_rebuilt(rng):
    """A global change (a 1e4 contrast over half the block) slows the kept hierarchy by more
    than stale_factor: the answer is still right, and the next solve rebuilds."""
    w = np.ones(N**3)
    s = solver(stale_factor=1.2)
    s.set_operator(diffusion(w))
    b = rng.normal(size=N**3)
    s.solve(b, np.zeros_like(b))
    w[rng.uniform(size=N**3) < 0.5] = 1e-4
    A2 = diffusion(w)
    s.set_operator(A2)
    x, st = s.solve(b, np.zeros_like(b))
    assert st.stale and relative_residual(A2, x, b) <= 1e-9 * 1.01
    assert s.reuse.rebuild_due
    _, again = s.solve(b, np.zeros_like(b))
    assert again.rebuilt and not again.stale and s.n_setups == 2
    assert not s.reuse.rebuild_due and s.reuse.fresh_rate > 0


def test_hierarchy_is_rebuilt_after_its_interval(rng):
    w = np.ones(N**3)
    s = solver(stale_factor=100.0, max_stale_solves=2)
    s.set_operator(diffusion(w))
    b = rng.normal(size=N**3)
    s.solve(b)
    kept = []
    for _ in range(3):
        w[rng.integers(N**3)] = 0.5
        s.set_operator(diffusion(w))
        kept.append(s.solve(b, np.zeros_like(b))[1].stale)
    assert kept == [True, True, False] and s.n_setups == 2


def test_no_reuse_rebuilds_on_every_change(rng):
    w = np.ones(N**3)
    s = solver()
    for _ in range(2):
        w[rng.integers(N**3)] = 0.5
        s.set_operator(diffusion(w))
        assert s.solve(rng.normal(size=N**3))[1].rebuilt
    assert s.n_setups == 2


def test_ritz_scaled_warm_start(rng):
    """A warm start off by a factor is rescaled to the solution exactly: no iteration left."""
    A = diffusion(np.ones(N**3))
    b = rng.normal(size=N**3)
    x_true = spla.spsolve(A.tocsc(), b)
    s = solver()
    s.set_operator(A)
    _, st = s.solve(b, 3.0 * x_true)
    assert st.iterations == 0
    plain = solver()
    plain.ritz = False
    plain.set_operator(A)
    assert plain.solve(b, 3.0 * x_true)[1].iterations > 0


def test_convergence_rate():
    assert convergence_rate(1.0, 1e-8, 4) == 2.0
    assert convergence_rate(1.0, 1e-8, 0) == 0.0
    assert convergence_rate(1e-9, 1e-8, 3) == 0.0


def test_deferred_near_nullspace_is_made_once_and_only_when_built(rng):
    """Candidates given as a maker are formed on the first build, not before, and only once;
    the hierarchy is the one the same candidates given outright build."""
    A = diffusion(np.ones(N**3))
    B = np.ones((N**3, 1))
    calls = []

    def make() -> np.ndarray:
        calls.append(1)
        return B.copy()

    lazy, eager = solver(stale_factor=2.0), solver(stale_factor=2.0)
    lazy.defer_near_nullspace(make)
    eager.near_nullspace = B
    lazy.set_operator(A)
    eager.set_operator(A)
    assert not calls  # no build yet
    b = rng.normal(size=N**3)
    x_lazy, _ = lazy.solve(b)
    x_eager, _ = eager.solve(b)
    assert calls == [1]
    assert np.array_equal(x_lazy, x_eager)
    lazy.set_operator(diffusion(np.full(N**3, 1.01)))  # kept: nothing new to make
    lazy.solve(b)
    assert calls == [1] and np.array_equal(lazy.near_nullspace, B)
