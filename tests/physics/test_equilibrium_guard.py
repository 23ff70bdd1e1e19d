"""The equilibrium guard: matrix-free K u against the assembled K, residuals, CG correction."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from diathermy.fem.geometry import structured_geometry
from diathermy.mesh import Grid, build_tet_mesh
from diathermy.physics.equilibrium_guard import (
    GuardPreconditioners,
    correct,
    equilibrium_residual,
    internal_force,
    jacobi_cg,
)
from diathermy.physics.mechanics import MechanicsSolver
from diathermy.physics.strain_energy import relative_strain_energy_error, strain_energy_density

P0 = 101325.0
NU = 0.4


@pytest.fixture(scope="module")
def problem():  # noqa: ANN201
    """A 5x6x9 block, a stiff/ersatz E pattern, a pressure bump; FEM solved to rtol 1e-12."""
    mesh = build_tet_mesh(Grid((5, 6, 9), size_m=(0.02, 0.01, 0.01)))
    geom = structured_geometry(mesh.points, mesh.tets, mesh.shape_id)
    rng = np.random.default_rng(3)
    centroid_z = mesh.points[mesh.tets].mean(axis=1)[:, 2]
    healthy = ~((centroid_z > 0.008) & (rng.uniform(size=mesh.n_tets) < 0.5))
    E = np.where(healthy, 2.7e5, 0.27)
    x, y, z = mesh.points.T
    p = P0 + 3e5 * np.exp(-((x - 0.01) ** 2 + (y - 0.005) ** 2 + (z - 0.01) ** 2) / 2e-5)
    solver = MechanicsSolver(mesh, E, NU, healthy=healthy, rtol=1e-12)
    assert solver.fragments.loose.any()  # the pattern leaves loose bits: the solver removes them
    u = solver.solve(p, P0).u
    free = ~solver.constrained.reshape(-1, 3)
    # the operator's own E and healthy mask (loose fragments at the ersatz level)
    return mesh, geom, solver.youngs_modulus_pa, solver.healthy, p, solver, u, free


def test_internal_force_is_the_assembled_stiffness_times_u(problem) -> None:  # noqa: ANN001
    mesh, geom, E, _, _, solver, _, free = problem
    u = np.random.default_rng(0).normal(size=(mesh.n_nodes, 3)) * 1e-5
    u[~free] = 0.0  # K's constrained rows are identity-like: compare free DOFs of a clamped u
    reference = (solver.K @ u.ravel()).reshape(-1, 3)
    got = internal_force(geom, mesh.tets, u, E, NU)
    np.testing.assert_allclose(
        got[free], reference[free], rtol=1e-9, atol=1e-12 * abs(reference).max()
    )


def test_residual_is_zero_at_equilibrium_and_scales_with_the_error(problem) -> None:  # noqa: ANN001
    mesh, geom, E, healthy, p, solver, u, free = problem
    args = (p, P0, E, NU, healthy, free)
    assert equilibrium_residual(geom, mesh.tets, u, *args) < 1e-9
    # K (1.1 u) - f = 0.1 K u = 0.1 f: the relative residual is exactly 0.1
    assert equilibrium_residual(geom, mesh.tets, 1.1 * u, *args) == pytest.approx(0.1, rel=1e-6)
    # the assembled operator (one mat-vec) and the matrix-free pass give the same residual
    noisy = u * (1 + 0.2 * np.random.default_rng(2).normal(size=u.shape))
    assert equilibrium_residual(geom, mesh.tets, noisy, *args, stiffness=solver.K) == pytest.approx(
        equilibrium_residual(geom, mesh.tets, noisy, *args), rel=1e-9
    )
    zero = np.zeros_like(u)
    assert (
        equilibrium_residual(geom, mesh.tets, zero, np.full_like(p, P0), P0, E, NU, healthy, free)
        == 0.0
    )


@pytest.mark.parametrize("kind", ["amg", "jacobi"])
def test_correction_reaches_the_tolerance_and_cuts_the_energy_error(problem, kind) -> None:  # noqa: ANN001
    mesh, geom, E, healthy, p, solver, u, free = problem
    rng = np.random.default_rng(1)
    u0 = u * (1 + 0.3 * rng.normal(size=u.shape))  # a poor surrogate: 30 % noise per DOF
    W_ref = strain_energy_density(geom.grads, mesh.tets, u, E, NU)
    before = relative_strain_energy_error(
        strain_energy_density(geom.grads, mesh.tets, u0, E, NU), W_ref
    )
    c = correct(solver, u0, p, P0, tol=1e-3, maxiter=500, preconditioner=GuardPreconditioners(kind))
    assert c.residual_before > 1e-2
    assert c.residual_after <= 1e-3
    assert c.residual_after == pytest.approx(
        equilibrium_residual(geom, mesh.tets, c.u, p, P0, E, NU, healthy, free), rel=1e-6
    )
    assert 0 < c.iterations < 500
    after = relative_strain_energy_error(
        strain_energy_density(geom.grads, mesh.tets, c.u, E, NU), W_ref
    )
    assert after < 0.1 * before
    assert np.all(c.u[~free] == 0.0)


def test_no_iterations_when_the_start_already_passes(problem) -> None:  # noqa: ANN001
    _, _, _, _, p, solver, u, _ = problem
    c = correct(
        solver, u, p, P0, tol=1e-3, maxiter=50, preconditioner=GuardPreconditioners("jacobi")
    )
    assert c.iterations == 0 and c.residual_after < 1e-9


def test_unknown_preconditioner_is_refused() -> None:
    with pytest.raises(ValueError, match="amg"):
        GuardPreconditioners("ilu")  # type: ignore[arg-type]


def test_jacobi_cg_on_the_assembled_stiffness_reaches_the_tolerance(problem) -> None:  # noqa: ANN001
    from diathermy.fem.elastic import eigenstress_load

    mesh, geom, E, healthy, p, solver, u, free = problem
    K = solver.assembler.stiffness(E, NU)  # unconstrained: jacobi_cg masks the clamped DOFs
    f = eigenstress_load(geom, mesh.tets, mesh.n_nodes, p - P0, healthy)
    u0 = u * (1 + 0.3 * np.random.default_rng(4).normal(size=u.shape))
    c = jacobi_cg(K, f, u0, free, tol=1e-3, maxiter=2000)
    assert c.residual_before > 1e-2 and c.residual_after <= 1e-3 and c.iterations > 0
    assert c.residual_after == pytest.approx(
        equilibrium_residual(geom, mesh.tets, c.u, p, P0, E, NU, healthy, free), rel=1e-6
    )
    assert np.all(c.u[~free] == 0.0)
    W_ref = strain_energy_density(geom.grads, mesh.tets, u, E, NU)
    err = relative_strain_energy_error(
        strain_energy_density(geom.grads, mesh.tets, c.u, E, NU), W_ref
    )
    assert err < 1e-2


def test_ritz_scale_recovers_the_amplitude_and_never_increases_the_energy_error(problem) -> None:  # noqa: ANN001
    from diathermy.physics.equilibrium_guard import ritz_scale

    mesh, geom, E, _, p, solver, u, free = problem
    f = solver.load(p, P0).reshape(-1, 3)
    K = solver.K

    def Ku(v: np.ndarray) -> np.ndarray:
        return (K @ v.ravel()).reshape(-1, 3)

    assert ritz_scale(f, Ku(0.3 * u), 0.3 * u, free) == pytest.approx(1 / 0.3, rel=1e-8)
    rng = np.random.default_rng(5)
    for _ in range(5):
        v = u * rng.uniform(0.2, 3.0) * (1 + 0.5 * rng.normal(size=u.shape))
        v[~free] = 0.0
        a = ritz_scale(f, Ku(v), v, free)

        def energy_error(w: np.ndarray) -> float:
            d = (u - w).ravel()
            return float(d @ (K @ d))

        assert energy_error(a * v) <= energy_error(v) * (1 + 1e-12)
    zero = np.zeros_like(u)
    assert ritz_scale(f, zero, zero, free) == 1.0


def _local_error(mesh, u: np.ndarray, free: np.ndarray, radius_m: float) -> np.ndarray:  # noqa: ANN001
    """u with a 40 % error on the nodes within ``radius_m`` of the pressure peak (a bad crater)."""
    near = np.linalg.norm(mesh.points - np.array([0.01, 0.005, 0.01]), axis=1) < radius_m
    u0 = u.copy()
    u0[near] *= 1.4
    u0[near] += 1e-7
    u0[~free] = 0.0
    return u0


def test_patch_correction_removes_an_error_inside_the_patch_exactly(problem) -> None:  # noqa: ANN001
    from diathermy.fem.elastic import eigenstress_load
    from diathermy.physics.patch_correction import node_graph, patch_correct, residual_patch

    mesh, geom, E, healthy, p, solver, u, free = problem
    K = solver.assembler.stiffness(E, NU)
    f = eigenstress_load(geom, mesh.tets, mesh.n_nodes, p - P0, healthy)
    u0 = _local_error(mesh, u, free, 0.003)
    Ku0 = (K @ u0.ravel()).reshape(-1, 3)
    r = np.where(free, f - Ku0, 0.0)
    # the residual of an error e is -K e: it lives on e's nodes and one ring around them, so
    # every node with a residual, plus a ring, holds all of e
    nodes = residual_patch(r, node_graph(K), threshold=1e-9, layers=1, max_nodes=mesh.n_nodes)
    assert 0 < nodes.size < mesh.n_nodes
    c = patch_correct(K, f, u0, Ku0, free, nodes)
    assert c.nodes == nodes.size and c.residual_before > 0.1
    np.testing.assert_allclose(c.u, u, rtol=0, atol=1e-9 * abs(u).max())
    assert c.residual_after < 1e-8
    np.testing.assert_allclose(c.Ku, (K @ c.u.ravel()).reshape(-1, 3), atol=1e-12 * abs(f).max())
    outside = np.setdiff1d(np.arange(mesh.n_nodes), nodes)
    assert np.array_equal(c.u[outside], u0[outside]) and np.all(c.u[~free] == 0.0)


def test_patch_correction_of_a_wider_error_solves_its_patch_and_cuts_the_energy_error(
    problem,  # noqa: ANN001
) -> None:
    from diathermy.fem.elastic import eigenstress_load
    from diathermy.physics.patch_correction import node_graph, patch_correct, residual_patch

    mesh, geom, E, healthy, p, solver, u, free = problem
    K = solver.assembler.stiffness(E, NU)
    f = eigenstress_load(geom, mesh.tets, mesh.n_nodes, p - P0, healthy)
    u0 = _local_error(mesh, u, free, 0.006)
    Ku0 = (K @ u0.ravel()).reshape(-1, 3)
    nodes = residual_patch(
        np.where(free, f - Ku0, 0.0), node_graph(K), threshold=0.1, layers=1, max_nodes=150
    )
    assert 0 < nodes.size <= 150
    c = patch_correct(K, f, u0, Ku0, free, nodes)
    # equilibrium holds exactly on the patch's free DOFs, and the global residual falls
    on_patch = np.zeros(mesh.n_nodes, bool)
    on_patch[nodes] = True
    r_after = np.where(free, f - (K @ c.u.ravel()).reshape(-1, 3), 0.0)
    assert np.abs(r_after[on_patch]).max() < 1e-9 * np.abs(f).max()
    assert c.residual_after < 0.5 * c.residual_before
    W_ref = strain_energy_density(geom.grads, mesh.tets, u, E, NU)

    def err(v: np.ndarray) -> float:
        return relative_strain_energy_error(
            strain_energy_density(geom.grads, mesh.tets, v, E, NU), W_ref
        )

    assert err(c.u) < 0.5 * err(u0)

    def energy_norm(v: np.ndarray) -> float:  # ||u* - v||_K^2, the error a Galerkin step lowers
        e = (u - v).ravel()
        return float(e @ (K @ e))

    assert energy_norm(c.u) < energy_norm(u0)


def test_an_empty_patch_changes_nothing(problem) -> None:  # noqa: ANN001
    from diathermy.physics.patch_correction import node_graph, patch_correct, residual_patch

    mesh, _, E, _, _, solver, u, free = problem
    K = solver.assembler.stiffness(E, NU)
    zero = np.zeros_like(u)
    assert residual_patch(zero, node_graph(K), threshold=0.1, layers=2, max_nodes=10).size == 0
    c = patch_correct(K, zero, u, (K @ u.ravel()).reshape(-1, 3), free, np.zeros(0, np.int64))
    assert c.nodes == 0 and c.u is u


def test_residual_patch_grows_rings_and_respects_its_cap(problem) -> None:  # noqa: ANN001
    from diathermy.physics.patch_correction import node_graph, residual_patch

    mesh, _, E, _, _, solver, _, _ = problem
    graph = node_graph(solver.assembler.stiffness(E, NU))
    r = np.zeros((mesh.n_nodes, 3))
    r[100, 1] = 2.0
    r[7, 0] = 1.0  # half the peak
    assert residual_patch(r, graph, threshold=0.6, layers=0, max_nodes=99).tolist() == [100]
    assert residual_patch(r, graph, threshold=0.4, layers=0, max_nodes=99).tolist() == [7, 100]
    ring = residual_patch(r, graph, threshold=0.6, layers=1, max_nodes=99)
    assert set(ring) == set(graph[100].indices) and 100 in ring  # the node and its neighbours
    capped = residual_patch(r, graph, threshold=0.4, layers=1, max_nodes=ring.size)
    assert np.array_equal(capped, ring)  # too big with both seeds: the stronger one stays
    for bad in ({"threshold": 0.0}, {"threshold": 1.5}, {"layers": -1}, {"max_nodes": 0}):
        kw = {"threshold": 0.1, "layers": 1, "max_nodes": 10, **bad}
        with pytest.raises(ValueError, match="patch"):
            residual_patch(r, graph, **kw)  # type: ignore[arg-type]


def _grid_graph(n: int) -> sp.csr_matrix:
    """A path of n nodes (each its own neighbour, as a stiffness pattern has it)."""
    return sp.diags([1, 1, 1], [-1, 0, 1], shape=(n, n), format="csr", dtype=np.int8)


@settings(max_examples=60, deadline=None)
@given(
    values=st.lists(st.floats(0.0, 1e6, allow_subnormal=False), min_size=1, max_size=60),
    threshold=st.floats(1e-6, 1.0),
    layers=st.integers(0, 4),
    max_nodes=st.integers(1, 80),
)
def test_residual_patch_properties(values, threshold, layers, max_nodes) -> None:  # noqa: ANN001
    from diathermy.physics.patch_correction import residual_patch

    n = len(values)
    r = np.zeros((n, 3))
    r[:, 2] = values
    patch = residual_patch(
        r, _grid_graph(n), threshold=threshold, layers=layers, max_nodes=max_nodes
    )
    if max(values) == 0.0:
        assert patch.size == 0
        return
    assert np.array_equal(patch, np.unique(patch))  # sorted, no repeats
    assert int(np.argmax(values)) in patch or values.count(max(values)) > 1
    # within the cap, unless one seed's rings alone exceed it
    assert patch.size <= max(max_nodes, 2 * layers + 1)


def test_a_singular_patch_leaves_u_unchanged(problem) -> None:  # noqa: ANN001
    from diathermy.fem.elastic import eigenstress_load
    from diathermy.physics.patch_correction import node_graph, patch_correct, residual_patch

    mesh, geom, E, healthy, p, solver, u, free = problem
    E0 = np.where(healthy, E, 0.0)  # removed tissue with no stiffness at all: K_PP singular
    K = solver.assembler.stiffness(E0, NU)
    f = eigenstress_load(geom, mesh.tets, mesh.n_nodes, p - P0, healthy)
    u0 = _local_error(mesh, u, free, 0.02)  # the whole top: the patch takes in the void
    Ku0 = (K @ u0.ravel()).reshape(-1, 3)
    nodes = residual_patch(
        np.where(free, f - Ku0, 0.0), node_graph(K), threshold=1e-12, layers=3, max_nodes=10**6
    )
    c = patch_correct(K, f, u0, Ku0, free, nodes)
    assert nodes.size == mesh.n_nodes  # the fixture's loose bits float free: K_PP is singular
    assert c.nodes == 0 and c.u is u0 and c.residual_after == c.residual_before
