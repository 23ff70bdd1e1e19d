"""The heat step against analytic solutions (PHYSICS.md 6b), its maximum principle and energy balance."""

from __future__ import annotations

import numpy as np
import pytest

from diathermy.errors import SceneError
from diathermy.fem.edges import edge_stiffness
from diathermy.fem.geometry import structured_geometry
from diathermy.mesh import Grid, build_tet_mesh
from diathermy.physics.heat_operator import assemble_heat_operator, heat_mesh, heat_rhs
from diathermy.physics.thermal import HeatStepper
from tests.physics.convective_column import T_INF_K, T_INITIAL_K, column_max_error

K_TISSUE = 0.574  # W/(m K), at x = 0
RHO_C = 1019.8 * 3441.0  # J/(m^3 K)
T_AMB = 298.15
T0 = 310.15


def make(shape, size_m):
    mesh = build_tet_mesh(Grid(shape, size_m=size_m))
    geom = structured_geometry(mesh.points, mesh.tets, mesh.shape_id)
    return mesh, heat_mesh(mesh, geom, edge_stiffness(geom, mesh.tets, mesh.n_nodes))


@pytest.fixture(scope="module")
def cube():
    """13^3 nodes, dx = 1.25 mm: CN stays monotone up to dt ~ 3 s here, not at 10 s."""
    return make((13, 13, 13), (0.015, 0.015, 0.015))


def test_semi_infinite_solid_with_convective_surface():
    """(T - Ti)/(T_inf - Ti) = erfc(xi) - exp(-xi^2) erfcx(xi + beta) at t = 60 s (beta = 2.7).

    A 30 mm column (h_z = 0.25 mm, dt = 0.1 s), convective top, insulated elsewhere; the
    heat reaches ~10 mm by then. Tolerance: 0.1 % of T_inf - Ti (measured 0.022 %).
    """
    mesh, hm = make((121, 3, 3), (1e-3, 1e-3, 0.03))
    err = column_max_error(mesh, hm, k=K_TISSUE, rho_c=RHO_C)
    assert err < 1e-3 * (T_INF_K - T_INITIAL_K)


def test_steady_slab_with_uniform_source():
    """Half-slab, insulated mid-plane z = 0, convective top z = L: T = T_inf + Q L/h + Q (L^2 - z^2)/(2k).

    Large steps (theta -> 1) reach the steady state. The lumped source and Robin terms are
    uneven along the column's edges, so the 3-D solution is not exactly 1-D: error O(h^2),
    below 0.03 % of the temperature rise at h = L/20.
    """
    L, Q, h = 0.01, 1e5, 25.0
    errors = []
    for nz in (6, 11, 21):
        dz = L / (nz - 1)
        mesh, hm = make((nz, 2, 2), (dz, dz, L))
        stepper = HeatStepper(hm, h_w_per_m2_k={"z+": h}, t_ambient_k=T_AMB)
        T = np.full(mesh.n_nodes, T_AMB)
        for _ in range(5):
            T = stepper.step(T, 1e9, rho_c=RHO_C, k=K_TISSUE, q=np.full(mesh.n_tets, Q)).T
        z = mesh.points[:, 2]
        exact = T_AMB + Q * L / h + Q * (L**2 - z**2) / (2 * K_TISSUE)
        errors.append(np.abs(T - exact).max() / (exact.max() - T_AMB))
    slopes = -np.diff(np.log(errors)) / np.log(2.0)
    assert np.all(slopes >= 1.8) and errors[-1] < 3e-4, (errors, slopes)


@pytest.mark.parametrize("dt", [1e-4, 0.03, 1.0, 10.0])
def test_maximum_principle(cube, dt):
    """No source: every step stays within [min(T, T_amb), max(T, T_amb)] of the step before."""
    mesh, hm = cube
    T = np.full(mesh.n_nodes, T0)
    T[mesh.n_nodes // 2] = 1000.0  # a single hot node: the hardest case for CN
    stepper = HeatStepper(hm, t_ambient_k=T_AMB)
    for _ in range(5):
        res = stepper.step(T, dt, rho_c=RHO_C, k=K_TISSUE)
        lo, hi = min(T.min(), T_AMB), max(T.max(), T_AMB)
        assert res.T.min() >= lo - 1e-9 * hi and res.T.max() <= hi + 1e-9 * hi
        T = res.T
    fell_back = res.stats.fallback_nodes.size
    assert (fell_back > 0) == (dt == 10.0)  # CN is kept wherever it is monotone


@pytest.mark.parametrize("dt", [0.03, 10.0])
def test_rhs_from_the_matrix_is_the_edge_form(cube, rng, dt):
    """heat_rhs reads K_(1-theta) T off the step's matrix (and the fallback's steep edges): the
    same right-hand side as the explicit half summed over every edge, with and without theta
    raised above 1/2."""
    mesh, hm = cube
    h = {"z+": 25.0, "x-": 10.0, "x+": 5.0, "y-": 0.0, "y+": 40.0, "z-": 0.0}
    stepper = HeatStepper(hm, h_w_per_m2_k=h, t_ambient_k=T_AMB)
    rho_c = RHO_C * rng.uniform(0.8, 1.2, mesh.n_nodes)
    k = K_TISSUE * rng.uniform(0.5, 2.0, mesh.n_tets)
    op, _ = stepper.operator(dt, rho_c, k)
    assert (op.steep_edges.size > 0) == (dt == 10.0)
    T = rng.uniform(300.0, 380.0, mesh.n_nodes)
    load = rng.normal(size=mesh.n_nodes)
    edge_form = (
        op.mass / op.dt_s * T
        - hm.stiffness.apply((1.0 - op.theta_edge) * op.w, T)
        - (1.0 - op.theta) * op.robin * T
        + op.robin * T_AMB
        + load
    )
    rhs = heat_rhs(op, hm.stiffness, T, T_AMB, load)
    assert np.abs(rhs - edge_form).max() <= 1e-12 * np.abs(op.mass / op.dt_s * T).max()


def test_plain_crank_nicolson_is_not_monotone_at_large_steps(cube):
    """Without the fallback the hot node overshoots far below the ambient temperature."""
    mesh, hm = cube
    T = np.full(mesh.n_nodes, T0)
    T[mesh.n_nodes // 2] = 1000.0
    res = HeatStepper(hm, t_ambient_k=T_AMB, monotone=False).step(T, 10.0, rho_c=RHO_C, k=K_TISSUE)
    assert res.T.min() < T_AMB - 100.0
    assert res.stats.fallback_nodes.size == 0 and res.stats.theta_max == 0.5


def test_energy_balance_closes(cube, rng):
    """stored = Joule + extra - convective loss, with varying coefficients and theta > 1/2."""
    mesh, hm = cube
    h = {"z+": 25.0, "x-": 10.0, "x+": 5.0, "y-": 0.0, "y+": 40.0, "z-": 0.0}
    stepper = HeatStepper(hm, h_w_per_m2_k=h, t_ambient_k=T_AMB)
    T = rng.uniform(300.0, 380.0, mesh.n_nodes)
    rho_c = RHO_C * rng.uniform(0.8, 1.2, mesh.n_nodes)
    k = K_TISSUE * rng.uniform(0.5, 1.5, mesh.n_tets)
    q = rng.uniform(0.0, 1e6, mesh.n_tets)
    extra = -rng.uniform(0.0, 1e-2, mesh.n_nodes)
    for dt in (0.03, 10.0):
        res = stepper.step(T, dt, rho_c=rho_c, k=k, q=q, source_w=extra)
        e = res.energy
        assert e.joule_j == pytest.approx(dt * np.dot(q, hm.geom.volumes), rel=1e-12)
        assert abs(e.imbalance_j) < 1e-8 * (abs(e.stored_j) + e.joule_j + abs(e.convective_loss_j))
        assert e.convective_loss_j > 0 and e.extra_j < 0
    assert res.stats.fallback_nodes.size > 0


def test_insulated_block_conserves_the_joule_energy(cube, rng):
    mesh, hm = cube
    stepper = HeatStepper(hm, h_w_per_m2_k=0.0, t_ambient_k=T_AMB)
    q = rng.uniform(0.0, 1e6, mesh.n_tets)
    res = stepper.step(np.full(mesh.n_nodes, T0), 1.0, rho_c=RHO_C, k=K_TISSUE, q=q)
    assert res.energy.convective_loss_j == 0.0
    assert res.energy.stored_j == pytest.approx(np.dot(q, hm.geom.volumes), rel=1e-9)


def test_preconditioner_follows_diagonal_dominance(cube, rng):
    """Jacobi at small dt, AMG at large dt; forcing either gives the same temperature."""
    mesh, hm = cube
    T = rng.uniform(300.0, 350.0, mesh.n_nodes)
    for dt, expected in ((0.03, "jacobi"), (1e4, "amg")):
        results = {}
        for pc in ("auto", "jacobi", "amg"):
            stepper = HeatStepper(hm, preconditioner=pc, t_ambient_k=T_AMB)
            results[pc] = stepper.step(T, dt, rho_c=RHO_C, k=K_TISSUE)
        assert results["auto"].stats.preconditioner == expected
        assert np.allclose(results["jacobi"].T, results["amg"].T, rtol=1e-8, atol=0)


def test_operator_reused_until_coefficients_change(cube):
    mesh, hm = cube
    stepper = HeatStepper(hm)
    T = np.full(mesh.n_nodes, T0)
    first = stepper.step(T, 0.03, rho_c=RHO_C, k=np.full(mesh.n_tets, K_TISSUE))
    same = stepper.step(first.T, 0.03, rho_c=np.full(mesh.n_nodes, RHO_C), k=K_TISSUE)
    changed = stepper.step(same.T, 0.03, rho_c=1.01 * RHO_C, k=K_TISSUE)
    assert first.stats.assembly_s > 0 and same.stats.assembly_s == 0.0
    assert changed.stats.assembly_s > 0
    # the rebuilt operator (k's edge weights kept) equals a fresh one
    fresh = assemble_heat_operator(hm, 0.03, 1.01 * RHO_C, K_TISSUE, stepper.robin)
    kept = stepper.operator(0.03, 1.01 * RHO_C, K_TISSUE)[0]
    assert abs(kept.matrix - fresh.matrix).max() == 0.0


@pytest.mark.parametrize("dt", [0.03, 10.0])
def test_operator_update_equals_a_fresh_assembly_bit_for_bit(cube, rng, dt):
    """rho c changed on a few nodes and k on a few tets (tissue drying, a vapor pocket) updates
    the last operator where they reach instead of assembling it, exactly as assembling it does;
    at 10 s the monotone fallback raises theta near the changes too."""
    mesh, hm = cube
    stepper = HeatStepper(hm, h_w_per_m2_k=25.0)
    rc = np.full(mesh.n_nodes, RHO_C)
    k = np.full(mesh.n_tets, K_TISSUE)
    stepper.operator(dt, rc, k)
    for _ in range(3):
        rc, k = rc.copy(), k.copy()
        rc[rng.choice(mesh.n_nodes, 20, replace=False)] *= rng.uniform(0.2, 1.5, 20)
        k[rng.choice(mesh.n_tets, 40, replace=False)] *= rng.uniform(0.05, 2.0, 40)
        op, assembly_s = stepper.operator(dt, rc, k)
        assert assembly_s > 0 and stepper._incidence is not None  # the update path ran
        fresh = assemble_heat_operator(hm, dt, rc, k, stepper.robin)
        for name in ("mass", "w", "theta", "theta_edge", "scale", "off_diagonal", "steep_edges"):
            assert np.array_equal(getattr(op, name), getattr(fresh, name)), name
        assert np.array_equal(op.matrix.data, fresh.matrix.data)
        assert np.array_equal(op.scaled.data, fresh.scaled.data)
        assert op.dominance == fresh.dominance
    if dt > 1:
        assert op.fallback_nodes.size > 0
    bad = rc.copy()
    bad[7] = -RHO_C
    with pytest.raises(SceneError):
        stepper.operator(dt, bad, k)
    kept, assembly_s = stepper.operator(dt, rc, k)
    assert kept is op and assembly_s == 0.0  # the last operator is kept


def test_rejects_bad_coefficients(cube):
    mesh, hm = cube
    robin = hm.robin(25.0)
    with pytest.raises(SceneError):
        assemble_heat_operator(hm, 0.0, RHO_C, K_TISSUE, robin)
    with pytest.raises(SceneError):
        assemble_heat_operator(hm, 0.03, -RHO_C, K_TISSUE, robin)
    with pytest.raises(SceneError):
        assemble_heat_operator(hm, 0.03, RHO_C, np.full(mesh.n_tets, np.nan), robin)
    with pytest.raises(SceneError):
        hm.robin({"top": 25.0})
