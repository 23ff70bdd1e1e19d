"""The windowed polish (physics.polish_window): the window's block is the operator's, PCG on it
lowers the global energy-norm error to the best the window allows (all of it for a window over
the block), with a history of past answers lower still (to zero when the answer is among them),
and its box grows with the change and stays within its node budget."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from diathermy.fem.energy_cg import energy_cg
from diathermy.physics.local_solve import IncrementalSettings
from diathermy.physics.mechanics import DEFAULT_AMG_OPTIONS
from diathermy.physics.polish_window import (
    WindowBox,
    block_submatrix_plan,
    build_window,
    choose_box,
    nodes_in_box,
    window_correct,
)
from diathermy.physics.window_history import History, augmented_correct
from tests.physics.test_incremental_mechanics import P0, _local, _setup


@pytest.fixture(scope="module")
def case():
    solver, u1, p2, graph = _setup()
    local = _local(solver, u1, p2, graph, IncrementalSettings(guard_tolerance=1e-12))
    f = solver.load(p2, P0)
    A, s = solver.krylov.A, solver.scale
    b = f * s
    x_true, info = spla.cg(A, b, rtol=1e-12, atol=0.0, maxiter=5000)
    assert info == 0
    return solver, local, A, b, x_true


def _energy_error(A, x, x_true) -> float:  # noqa: ANN001
    e = x - x_true
    return float(np.sqrt(e @ (A @ e) / (x_true @ (A @ x_true))))


def test_the_window_block_is_the_operators_block(case):
    solver, local, A, _, _ = case
    pts = solver.mesh.points
    box = choose_box(pts, local.patch_nodes, 0.01, pts.shape[0])
    nodes = nodes_in_box(pts, box.lo, box.hi)
    positions, indptr, indices = block_submatrix_plan(A.indptr, A.indices, nodes, pts.shape[0])
    dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
    sub = sp.bsr_matrix((A.data[positions], indices, indptr), shape=(dofs.size, dofs.size))
    expected = A.tocsr()[dofs][:, dofs]
    assert abs(sub.tocsr() - expected).max() == 0.0
    assert sub.nnz == expected.nnz


def test_window_correction_lowers_the_global_error_to_the_windows_best(case):
    solver, local, A, b, x_true = case
    s = solver.scale
    x0 = local.u.ravel() / s
    r = b - A @ x0
    norm_sq = float(x0 @ (b - r))
    pts, n = solver.mesh.points, solver.mesh.n_nodes

    def window(margin_m: float):  # noqa: ANN202
        box = choose_box(pts, local.patch_nodes, margin_m, n)
        return build_window(
            A, solver.krylov.near_nullspace, pts, box, DEFAULT_AMG_OPTIONS,
            solver.youngs_modulus_pa, solver.healthy,
        )  # fmt: skip

    before = _energy_error(A, x0, x_true)
    part = window(0.01)
    assert 0 < part.nodes.size < n
    errors = []
    for k in (1, 3, 60):
        res = window_correct(part, A, r, norm_sq, tol=1e-12, maxiter=k)
        x = x0.copy()
        x[part.dofs] += res.x
        errors.append(_energy_error(A, x, x_true))
    # CG minimises the same energy over the window's corrections: it never goes up, and it
    # reaches the best correction the window allows (the exact solve of its block)
    assert errors[0] < before
    assert all(e2 <= e1 * (1 + 1e-12) for e1, e2 in zip(errors, errors[1:], strict=False))
    exact = x0.copy()
    exact[part.dofs] += spla.spsolve(part.matrix(A).tocsc(), r[part.dofs])
    assert errors[-1] == pytest.approx(_energy_error(A, exact, x_true), rel=1e-3)
    # the estimate is relative to the whole answer's norm (the correction's own is 0 at the
    # start, which no tolerance would pass), so a loose tolerance stops early
    loose = window_correct(part, A, r, norm_sq, tol=0.5 * before, maxiter=60)
    assert loose.estimate <= 0.5 * before and loose.iterations < 3
    # a window over the whole block is the global solve
    whole = window(1.0)
    assert whole.nodes.size == n
    res = window_correct(whole, A, r, norm_sq, tol=1e-9, maxiter=200)
    assert _energy_error(A, x0 + res.x, x_true) < 1e-6


def test_the_v_cycle_smooths_the_operator_it_is_asked_to_solve(case):
    """A window kept while the operator changes (a cut: the stiffness of a few tets drops)
    takes each step's block as its V-cycle's fine level: bit for bit that block, and PCG
    converges faster than with the block the hierarchy was built for."""
    solver, local, A, b, _ = case
    pts, n = solver.mesh.points, solver.mesh.n_nodes
    w = build_window(
        A, solver.krylov.near_nullspace, pts, choose_box(pts, local.patch_nodes, 0.01, n),
        DEFAULT_AMG_OPTIONS, solver.youngs_modulus_pa, solver.healthy,
    )  # fmt: skip
    built = w.hierarchy.levels[0].A
    # soften the coupling of half the window's nodes 100-fold (same pattern, still SPD: the
    # scaled operator of a block whose stiffness dropped there), stiffen its diagonal a little
    A2 = A.copy()
    rows = np.repeat(np.arange(n), np.diff(A.indptr))
    soft = np.zeros(n, dtype=bool)
    soft[w.nodes[: w.nodes.size // 2]] = True
    off = rows != A.indices
    A2.data[off & soft[rows] & soft[A.indices]] *= 1e-2
    diag = ~off
    A2.data[diag & soft[rows]] *= 1.0 + 1e-3
    x_true = spla.spsolve(A2.tocsc(), b)
    r = b - A2 @ (0.9 * x_true)
    norm_sq = float(x_true @ (A2 @ x_true))
    res = window_correct(w, A2, r, norm_sq, tol=1e-8, maxiter=200)
    fine = w.hierarchy.levels[0].A
    assert fine is not built
    assert np.array_equal(fine.data, w.matrix(A2).data)
    assert np.array_equal(fine.indices, w.matrix(A2).indices)
    w.hierarchy.levels[0].A = built  # the V-cycle as it was built: PCG on the new block
    stale = energy_cg(
        w.matrix(A2), r[w.dofs], np.zeros(w.dofs.size), w.preconditioner,
        tol=1e-8, maxiter=200, norm_sq=norm_sq,
    )  # fmt: skip
    assert res.estimate <= 1e-8 and stale.estimate <= 1e-8
    assert res.iterations < stale.iterations


def test_the_box_grows_with_the_change_and_keeps_its_node_budget():
    pts = np.stack(np.meshgrid(*(np.linspace(0, 0.1, 11),) * 3, indexing="ij"), -1).reshape(-1, 3)
    change = nodes_in_box(pts, np.full(3, 0.05), np.full(3, 0.05))
    wide = choose_box(pts, change, 0.02, pts.shape[0])
    assert np.allclose(wide.lo, 0.03) and np.allclose(wide.hi, 0.07)
    assert np.allclose(wide.inner_lo, 0.04) and np.allclose(wide.inner_hi, 0.06)
    assert wide.holds(np.full(3, 0.045), np.full(3, 0.055))
    assert not wide.holds(np.full(3, 0.035), np.full(3, 0.055))
    tight = choose_box(pts, change, 0.02, 27)  # 5^3 nodes at 0.02, 3^3 at 0.01
    assert nodes_in_box(pts, tight.lo, tight.hi).size <= 27
    back = WindowBox.from_array(tight.as_array())
    assert np.array_equal(back.as_array(), tight.as_array())


def test_a_window_needs_a_block_operator_and_nodes(case):
    solver, local, A, _, _ = case
    pts = solver.mesh.points
    far = WindowBox(*(np.full(3, 10.0),) * 4)
    with pytest.raises(ValueError, match="holds no node"):
        build_window(
            A, None, pts, far, DEFAULT_AMG_OPTIONS, solver.youngs_modulus_pa, solver.healthy
        )
    with pytest.raises(ValueError, match="3x3-block"):
        build_window(
            A.tocsr().tobsr(blocksize=(1, 1)), None, pts, far, DEFAULT_AMG_OPTIONS,
            solver.youngs_modulus_pa, solver.healthy,
        )  # fmt: skip


def test_spread_and_the_patch_residual_are_the_global_mat_vecs(case):
    """The polish reads the residual off the patch's K u and updates it from the window's own
    rows: both equal the global mat-vecs they stand for."""
    solver, local, A, b, _ = case
    s = solver.scale
    x0 = local.u.ravel() / s
    assert local.Ku is not None
    r = b - A @ x0
    np.testing.assert_allclose(b - s * local.Ku.ravel(), r, rtol=0, atol=1e-12 * np.abs(b).max())
    box = choose_box(solver.mesh.points, local.patch_nodes, 0.01, solver.mesh.n_nodes)
    w = build_window(
        A, None, solver.mesh.points, box, DEFAULT_AMG_OPTIONS,
        solver.youngs_modulus_pa, solver.healthy,
    )  # fmt: skip
    d = np.random.default_rng(1).standard_normal(w.dofs.size)
    full = np.zeros(A.shape[0])
    full[w.dofs] = d
    for Aw in (None, w.matrix(A)):  # the window's block built here, or the caller's
        np.testing.assert_allclose(
            w.spread(A, d, Aw), A @ full, rtol=0, atol=1e-12 * np.abs(A @ full).max()
        )


def test_the_history_lowers_the_error_below_the_windows_best(case):
    """The coupled PCG minimises over the window's DOFs and the history's span: never above the
    window alone, exact when the answer lies in that span, and the history it builds is an
    A-orthonormal basis with its products."""
    solver, local, A, b, x_true = case
    s = solver.scale
    x0 = local.u.ravel() / s
    r = b - A @ x0
    norm_sq = float(x0 @ (b - r))
    pts = solver.mesh.points
    w = build_window(
        A, solver.krylov.near_nullspace, pts,
        choose_box(pts, local.patch_nodes, 0.004, solver.mesh.n_nodes),
        DEFAULT_AMG_OPTIONS, solver.youngs_modulus_pa, solver.healthy,
    )  # fmt: skip
    assert 0 < w.nodes.size < solver.mesh.n_nodes

    def corrected(history) -> float:  # noqa: ANN001
        x = x0.copy()
        if history is None:
            res = window_correct(w, A, r, norm_sq, tol=1e-12, maxiter=400)
            x[w.dofs] += res.x
        else:
            hist = History.of(A, s, history, w)
            res, c = augmented_correct(w, A, hist, r, norm_sq, tol=1e-12, maxiter=400)
            x[w.dofs] += res.x
            x += hist.Z @ c
        return _energy_error(A, x, x_true)

    alone = corrected(None)
    assert alone > 1e-4  # the window cannot reach the far field
    rng = np.random.default_rng(3)
    shapes = [local.u * (1 + 0.1 * rng.standard_normal(local.u.shape)), local.u]
    assert corrected(shapes) <= alone * (1 + 1e-9)
    u_true = (x_true * s).reshape(-1, 3)
    assert corrected([local.u, u_true]) < 1e-6
    hist = History.of(A, s, [local.u, u_true, 2.0 * u_true], w)
    assert hist.size == 2  # the parallel third is dropped
    np.testing.assert_allclose(hist.Z.T @ hist.AZ, np.eye(2), atol=1e-9)
    np.testing.assert_allclose(hist.AZ, A @ hist.Z, atol=1e-9 * np.abs(hist.AZ).max())
    assert np.all(hist.Z[w.dofs] == 0.0)  # the window's DOFs span that part
    held = solver.constrained
    lifted = [local.u + 1e-6]  # a (corrupt) history that moves held DOFs: they stay held
    assert np.all(History.of(A, s, lifted, w, constrained=held).Z[held] == 0.0)


def test_the_history_takes_a_known_product(case):
    """A product the caller has (the Ritz start's K u) stands for the block product's column."""
    solver, local, A, _, _ = case
    s = solver.scale
    pts = solver.mesh.points
    w = build_window(
        A, None, pts, choose_box(pts, local.patch_nodes, 0.004, solver.mesh.n_nodes),
        DEFAULT_AMG_OPTIONS, solver.youngs_modulus_pa, solver.healthy,
    )  # fmt: skip
    shapes = [local.u, 0.5 * local.u + 1e-6]
    shapes[1][solver.constrained.reshape(-1, 3)] = 0.0
    known = History.of(A, s, shapes, w, first_product=s * (solver.K @ local.u.ravel()))
    computed = History.of(A, s, shapes, w)
    v = np.random.default_rng(2).standard_normal(A.shape[0])
    for h in (known, computed):  # the A-orthogonal projection on the span, sign-free
        np.testing.assert_allclose(h.Z.T @ h.AZ, np.eye(h.size), atol=1e-9)
    np.testing.assert_allclose(
        known.Z @ (known.AZ.T @ v), computed.Z @ (computed.AZ.T @ v), rtol=1e-7, atol=1e-12
    )
