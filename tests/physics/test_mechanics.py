"""The elastostatic solve against PHYSICS.md section 6c-e, loose fragments and near-incompressibility."""

from __future__ import annotations

import numpy as np
import pytest

from diathermy.errors import SceneError, SolverDivergedError
from diathermy.fem.elastic import eigenstress_load, lame_parameters, rigid_body_modes, strain
from diathermy.mesh import Grid, build_tet_mesh
from diathermy.physics.constraints import Constraints, clamped_bottom, rollers
from diathermy.physics.fragments import find_fragments
from diathermy.physics.mechanics import MechanicsSolver
from diathermy.physics.strain_energy import strain_energy_density

E, NU, P0 = 0.27e6, 0.4, 101325.0
K_BULK = E / (3 * (1 - 2 * NU))
M_OED = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))
DP = 2e4
A_B = (2e4, 2e5)  # Delta p = a + b z of test 6e


@pytest.fixture(scope="module")
def mesh_s():
    return build_tet_mesh(Grid((17, 17, 33)))  # the S grid, H = 0.1 m


def nearest(mesh, xyz):
    return int(np.argmin(np.linalg.norm(mesh.points - np.asarray(xyz), axis=1)))


def stress(solver, u, dp_nodal):
    """sigma = C : eps(u) - mean_T(dp) I per tet (n_tets, 3, 3)."""
    eps = strain(solver.assembler.geom, solver.mesh.tets, u)
    lam, mu = lame_parameters(solver.youngs_modulus_pa, solver.poisson_ratio)
    tr = np.trace(eps, axis1=1, axis2=2)
    iso = lam * tr - dp_nodal[solver.mesh.tets].mean(axis=1)
    return iso[:, None, None] * np.eye(3) + 2 * mu[:, None, None] * eps


def test_6c_free_swelling_on_rollers(mesh_s):
    xc, yc = 0.1, 0.05
    pins = Constraints.on_nodes([nearest(mesh_s, [xc, yc, 0])], (0, 1))
    pins = pins + Constraints.on_nodes([nearest(mesh_s, [0.2, yc, 0])], (1,))
    solver = MechanicsSolver(mesh_s, E, NU, rollers(mesh_s, ("z-",)) + pins)
    res = solver.solve(np.full(mesh_s.n_nodes, P0 + DP))
    x, y, z = mesh_s.points.T
    exact = DP / (3 * K_BULK) * np.column_stack([x - xc, y - yc, z])
    assert np.abs(res.u - exact).max() < 0.01 * np.abs(exact).max()
    assert res.u[:, 2].max() == pytest.approx(1.48e-3, rel=2e-3)
    sig = stress(solver, res.u, np.full(mesh_s.n_nodes, DP))
    assert np.abs(sig).max() < 1e-6 * DP
    W = strain_energy_density(solver.assembler.geom.grads, mesh_s.tets, res.u, E, NU)
    assert np.allclose(W, DP**2 / (2 * K_BULK), rtol=1e-6)


def test_6d_laterally_confined_column(mesh_s):
    solver = MechanicsSolver(mesh_s, E, NU, rollers(mesh_s, ("z-", "x-", "x+", "y-", "y+")))
    res = solver.solve(np.full(mesh_s.n_nodes, P0 + DP))
    assert M_OED == pytest.approx(578.6e3, rel=1e-4)
    exact = DP * mesh_s.points[:, 2] / M_OED
    assert np.abs(res.u[:, 2] - exact).max() < 0.01 * exact.max()
    assert res.u[:, 2].max() == pytest.approx(3.46e-3, rel=2e-3)
    assert np.abs(res.u[:, :2]).max() < 1e-6 * exact.max()


def linear_pressure_case(n):
    mesh = build_tet_mesh(Grid((n, n, n), size_m=(0.1, 0.1, 0.1), origin_m=(-0.05, -0.05, 0)))
    x, y, z = mesh.points.T
    a, b = A_B
    dp = a + b * z
    exact = np.column_stack(
        [(a + b * z) * x, (a + b * z) * y, a * z + b * z**2 / 2 - b * (x**2 + y**2) / 2]
    ) / (3 * K_BULK)
    n0, n1, n2 = (nearest(mesh, p) for p in ([0, 0, 0], [0.05, 0, 0], [0, 0.05, 0]))
    dofs = np.array([3 * n0, 3 * n0 + 1, 3 * n0 + 2, 3 * n1 + 1, 3 * n1 + 2, 3 * n2 + 2])
    pins = Constraints(dofs, exact.ravel()[dofs])  # 3-2-1 pins at the exact (rigid) placement
    return mesh, dp, exact, MechanicsSolver(mesh, E, NU, pins, rtol=1e-10)


def test_6e_linear_pressure_is_stress_free():
    """Exactly stress-free in the weak form; the P1 solution's stress converges at O(h)."""
    errors, a_b = [], A_B
    for n in (5, 9, 17):
        mesh, dp, exact, solver = linear_pressure_case(n)
        # The exact solution satisfies the discrete weak form exactly: its strain is linear, so
        # int_T C : eps(u_exact) : eps(v) is the centroid value, and there it must equal the
        # eigenstress load (stress-free), for every P1 test function v.
        geom = solver.assembler.geom
        xc, yc, zc = mesh.centroids().T
        grad = np.zeros((mesh.n_tets, 3, 3))  # du_i/dx_k of the exact solution at centroids
        grad[:, 0, 0] = grad[:, 1, 1] = grad[:, 2, 2] = a_b[0] + a_b[1] * zc
        grad[:, 0, 2], grad[:, 1, 2] = a_b[1] * xc, a_b[1] * yc
        grad[:, 2, 0], grad[:, 2, 1] = -a_b[1] * xc, -a_b[1] * yc
        eps = (grad + np.swapaxes(grad, 1, 2)) / (6 * K_BULK)
        lam, mu = lame_parameters(E, NU)
        sig = lam * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(3) + 2 * mu * eps
        weak = np.zeros((mesh.n_nodes, 3))
        for i in range(3):
            contrib = geom.volumes[:, None] * np.einsum("ek,eak->ea", sig[:, i], geom.grads)
            weak[:, i] = np.bincount(mesh.tets.ravel(), contrib.ravel(), minlength=mesh.n_nodes)
        f = eigenstress_load(geom, mesh.tets, mesh.n_nodes, dp)
        assert np.abs(f - weak).max() < 1e-10 * np.abs(weak).max()
        res = solver.solve(P0 + dp)
        errors.append(np.abs(stress(solver, res.u, dp)).max() / dp.max())
        if n == 17:
            assert np.abs(res.u - exact).max() < 0.01 * np.abs(exact).max()
    rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert errors[-1] < 6e-3 and np.all(rates > 0.7) and rates[-1] > 0.9, (errors, rates)

    # Contrast: a body force -grad p alone misses the eigenstress at the free surfaces.
    mesh, dp, exact, solver = linear_pressure_case(9)
    body = np.zeros((mesh.n_nodes, 3))
    body[:, 2] = -2e5 * np.bincount(
        mesh.tets.ravel(), np.repeat(solver.assembler.geom.volumes / 4, 4), minlength=mesh.n_nodes
    )
    rhs = body.ravel().copy()
    rhs[solver.constraints.dofs] = solver.load(P0 + dp, P0)[solver.constraints.dofs]
    u_body, _ = solver._krylov.solve(rhs, np.zeros_like(rhs))
    wrong = np.abs(u_body.reshape(-1, 3) - exact).max() / np.abs(exact).max()
    assert wrong > 0.5


def test_operator_is_spd_on_free_dofs():
    mesh = build_tet_mesh(Grid((4, 4, 5)))
    solver = MechanicsSolver(mesh, E, NU)
    K = solver.K.toarray()
    assert np.allclose(K, K.T, atol=1e-12 * np.abs(K).max())
    free = ~solver.constrained
    w = np.linalg.eigvalsh(K[np.ix_(free, free)])
    assert w.min() > 1e-8 * w.max()
    c = solver.constrained
    assert np.all(K[np.ix_(c, free)] == 0) and np.all(np.diag(K)[c] > 0)


def test_pressure_load_has_no_net_force_and_bottom_holds_it(mesh_s, rng):
    solver = MechanicsSolver(mesh_s, E, NU)
    p = P0 + rng.uniform(0, 3e5, mesh_s.n_nodes)
    geom = solver.assembler.geom
    f = eigenstress_load(geom, mesh_s.tets, mesh_s.n_nodes, p - P0)
    assert np.abs(f.sum(axis=0)).max() < 1e-12 * np.abs(f).sum()
    res = solver.solve(p)
    bottom = mesh_s.side_nodes("z-")
    assert np.all(res.u[bottom] == 0)
    reaction = (solver.assembler.stiffness(E, NU) @ res.u.ravel()).reshape(-1, 3) - f
    off = np.ones(mesh_s.n_nodes, dtype=bool)
    off[bottom] = False
    scale = np.abs(f).sum()
    assert np.abs(reaction[off]).max() < 1e-6 * np.abs(f).max()  # equilibrium off the bottom
    assert np.abs(reaction[bottom].sum(axis=0)).max() < 1e-6 * scale  # no net force on the base


def test_hierarchy_reuse_and_warm_start(mesh_s, rng):
    solver = MechanicsSolver(mesh_s, E, NU)
    z = mesh_s.points[:, 2]
    p = P0 + 2e5 * np.exp(-(((mesh_s.points - [0.1, 0.05, 0.1]) ** 2).sum(1)) / 0.02**2) * (z > 0)
    cold = solver.solve(p)
    warm = solver.solve(p * (1 + 0.01 * rng.uniform(-1, 1, p.size)))
    assert cold.stats.rebuilt and not warm.stats.rebuilt
    assert warm.stats.iterations < cold.stats.iterations
    again = solver.solve(p, x0=np.zeros((mesh_s.n_nodes, 3)))
    assert np.allclose(again.u, cold.u, atol=1e-6 * np.abs(cold.u).max())


def slab_cut(mesh, z_lo, z_hi):
    zc = mesh.centroids()[:, 2]
    healthy = ~((zc > z_lo) & (zc < z_hi))
    return healthy, np.where(healthy, E, 1e-6 * E)


@pytest.mark.parametrize("policy", ["remove", "keep"])
def test_loose_fragment_does_not_break_the_solve(policy):
    mesh = build_tet_mesh(Grid((9, 9, 17)))
    healthy, Ee = slab_cut(mesh, 0.03, 0.05)  # everything above the slab floats
    fr = find_fragments(mesh, healthy, clamped_bottom(mesh).mask(3 * mesh.n_nodes))
    above = mesh.centroids()[:, 2] > 0.05
    assert fr.n_components == 2 and np.array_equal(fr.loose, above)
    solver = MechanicsSolver(mesh, Ee, NU, healthy=healthy, loose_fragments=policy, maxiter=300)
    p = P0 + 1e5 * (mesh.points[:, 2] > 0.06)
    res = solver.solve(p)
    assert np.all(np.isfinite(res.u)) and res.stats.residual <= 1e-8
    W = strain_energy_density(
        solver.assembler.geom.grads, mesh.tets, res.u, solver.youngs_modulus_pa, NU
    )
    if policy == "remove":
        assert not solver.healthy[above].any() and W[above].max() < 1e-3
        assert np.abs(res.u).max() < 1e-9  # no eigenstress left anywhere: nothing moves
    else:
        assert W[above].max() > 1e3  # the kept fragment swells and stores energy


def test_cut_without_fragment_is_not_loose():
    mesh = build_tet_mesh(Grid((9, 9, 17)))
    c = mesh.centroids()
    healthy = np.linalg.norm(c - [0.1, 0.05, 0.1], axis=1) > 0.03  # a crater in the top
    fr = find_fragments(mesh, healthy, clamped_bottom(mesh).mask(3 * mesh.n_nodes))
    assert fr.n_components == 1 and not fr.loose.any()
    solver = MechanicsSolver(mesh, np.where(healthy, E, 1e-6 * E), NU, healthy=healthy)
    res = solver.solve(np.full(mesh.n_nodes, P0 + DP))
    assert res.stats.iterations < 60


def test_nearly_incompressible_converges(mesh_s):
    solver = MechanicsSolver(mesh_s, E, 0.49)
    z = mesh_s.points[:, 2]
    res = solver.solve(P0 + 1e5 * z / 0.1)
    assert res.stats.iterations < 100 and np.all(np.isfinite(res.u))


def test_errors():
    mesh = build_tet_mesh(Grid((5, 5, 9)))
    with pytest.raises(SceneError, match="rigid"):
        MechanicsSolver(mesh, E, NU, rollers(mesh, ("z-",)))
    with pytest.raises(SceneError, match="Young"):
        MechanicsSolver(mesh, np.full(mesh.n_tets, -1.0), NU)
    solver = MechanicsSolver(mesh, E, NU, maxiter=1, rtol=1e-14)
    with pytest.raises(ValueError, match="shape"):
        solver.solve(np.zeros(3))
    with pytest.raises(SolverDivergedError):
        solver.solve(P0 + np.linspace(0, 1e5, mesh.n_nodes))


@pytest.mark.parametrize("consume", [False, True])
@pytest.mark.parametrize("graded", [False, True])
def test_updated_stiffness_equals_a_fresh_build_bit_for_bit(graded, consume):
    """A cut of a few tets updates the previous operator in place of assembling it again, and
    the matrix, its scaling and the solution are exactly those of a fresh build; a consumed
    base (its matrices taken over, not copied) refuses to solve or be updated again."""
    if graded:
        grid, radii = (
            Grid.graded((0.08, 0.03, 0.06), (0.12, 0.07, 0.1), 0.008),
            (8e-3, 0.012, 0.016),
        )
    else:
        grid, radii = Grid((9, 9, 17)), (0.012, 0.02, 0.03)
    mesh = build_tet_mesh(grid)
    c = mesh.centroids()
    base = MechanicsSolver(mesh, E, NU)
    solver = base
    for radius in radii:  # a growing crater: a chain of updates
        healthy = np.linalg.norm(c - [0.1, 0.05, 0.1], axis=1) > radius
        Ee = np.where(healthy, E, 1e-6 * E)
        previous = solver
        solver = MechanicsSolver(
            mesh, Ee, NU, healthy=healthy, assembler=base.assembler, base=solver,
            consume_base=consume,
        )  # fmt: skip
        assert previous.consumed == consume
        if consume:
            with pytest.raises(RuntimeError, match="handed"):
                previous.solve(np.full(mesh.n_nodes, P0))
            assert not previous.updatable_to(solver)
        fresh = MechanicsSolver(mesh, Ee, NU, healthy=healthy, assembler=base.assembler)
        assert solver.updated and not fresh.updated
        assert np.array_equal(solver.K.data, fresh.K.data)
        assert np.array_equal(solver.scale, fresh.scale)
        assert np.array_equal(solver._diag, fresh.K.diagonal())
        assert np.array_equal(solver.K_scaled.data, fresh.K_scaled.data)  # scaled in place too
        B = solver.krylov.near_nullspace  # made when asked: the rigid modes, scaled, held DOFs 0
        assert np.array_equal(B, fresh.krylov.near_nullspace)
        assert np.all(B[solver.constrained] == 0.0)
        free = ~solver.constrained
        modes = rigid_body_modes(mesh.points)
        assert np.allclose(B[free] * solver.scale[free, None], modes[free], rtol=1e-12, atol=0)
        p = P0 + DP * healthy.any() * np.ones(mesh.n_nodes)
        assert np.array_equal(solver.solve(p).u, fresh.solve(p).u)


def test_update_falls_back_to_a_fresh_build():
    mesh = build_tet_mesh(Grid((5, 5, 9)))
    base = MechanicsSolver(mesh, E, NU)
    everything = MechanicsSolver(mesh, 0.5 * E, NU, assembler=base.assembler, base=base)
    assert not everything.updated  # every tet changed: assembled anew
    lifted = Constraints.on_nodes(mesh.side_nodes("z-"), value_m=1e-4)
    moved = MechanicsSolver(mesh, E, NU, lifted, assembler=base.assembler, base=base)
    assert not moved.updated  # nonzero prescribed values: the lift needs the whole K
    other_nu = MechanicsSolver(mesh, E, 0.3, assembler=base.assembler, base=base)
    assert not other_nu.updated
