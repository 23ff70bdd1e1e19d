"""The analytic mechanics cases (PHYSICS.md 6c, 6d, 6e) on a graded grid: the graded elastic
assembly and eigenstress load reproduce the linear solutions P1 represents exactly."""

from __future__ import annotations

import numpy as np
import pytest

from diathermy.fem.elastic import eigenstress_load, lame_parameters
from diathermy.mesh import Grid, TetMesh, build_tet_mesh
from diathermy.physics.constraints import Constraints, rollers
from diathermy.physics.mechanics import MechanicsSolver
from diathermy.physics.strain_energy import strain_energy_density

E, NU, P0, DP = 0.27e6, 0.4, 101325.0, 2e4
K_BULK = E / (3 * (1 - 2 * NU))
M_OED = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))


@pytest.fixture(scope="module")
def mesh_g() -> TetMesh:
    """0.2 x 0.1 x 0.1 m, 2 mm cells over the centre of the top growing by 1.4 to <= 25 mm."""
    g = Grid.graded((0.09, 0.04, 0.09), (0.11, 0.06, 0.1), 2e-3, growth=1.4, max_cell_m=0.025)
    assert not g.is_uniform
    return build_tet_mesh(g)


def nearest(mesh: TetMesh, xyz) -> int:  # noqa: ANN001
    return int(np.argmin(np.linalg.norm(mesh.points - np.asarray(xyz), axis=1)))


def test_6c_free_swelling_on_rollers_is_exact(mesh_g):
    xc, yc = 0.1, 0.05
    pins = Constraints.on_nodes([nearest(mesh_g, [xc, yc, 0])], (0, 1))
    pins = pins + Constraints.on_nodes([nearest(mesh_g, [0.2, yc, 0])], (1,))
    solver = MechanicsSolver(mesh_g, E, NU, rollers(mesh_g, ("z-",)) + pins, rtol=1e-10)
    res = solver.solve(np.full(mesh_g.n_nodes, P0 + DP))
    x, y, z = mesh_g.points.T
    exact = DP / (3 * K_BULK) * np.column_stack([x - xc, y - yc, z])
    assert np.abs(res.u - exact).max() < 1e-6 * np.abs(exact).max()
    W = strain_energy_density(solver.assembler.geom.grads, mesh_g.tets, res.u, E, NU)
    assert np.allclose(W, DP**2 / (2 * K_BULK), rtol=1e-5)


def test_6d_laterally_confined_column_is_exact(mesh_g):
    sides = ("z-", "x-", "x+", "y-", "y+")
    solver = MechanicsSolver(mesh_g, E, NU, rollers(mesh_g, sides), rtol=1e-10)
    res = solver.solve(np.full(mesh_g.n_nodes, P0 + DP))
    exact = DP * mesh_g.points[:, 2] / M_OED
    assert np.abs(res.u[:, 2] - exact).max() < 1e-6 * exact.max()
    assert res.u[:, 2].max() == pytest.approx(3.46e-3, rel=2e-3)


def test_6e_linear_pressure_weak_form_holds_on_a_graded_grid(mesh_g):
    """The stress-free solution of Delta p = a + b z satisfies the discrete weak form exactly."""
    a, b = 2e4, 2e5
    geom = MechanicsSolver(mesh_g, E, NU).assembler.geom
    xc, yc, zc = mesh_g.centroids().T
    grad = np.zeros((mesh_g.n_tets, 3, 3))
    grad[:, 0, 0] = grad[:, 1, 1] = grad[:, 2, 2] = a + b * zc
    grad[:, 0, 2], grad[:, 1, 2] = b * xc, b * yc
    grad[:, 2, 0], grad[:, 2, 1] = -b * xc, -b * yc
    eps = (grad + np.swapaxes(grad, 1, 2)) / (6 * K_BULK)
    lam, mu = lame_parameters(E, NU)
    sig = lam * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(3) + 2 * mu * eps
    weak = np.zeros((mesh_g.n_nodes, 3))
    for i in range(3):
        contrib = geom.volumes[:, None] * np.einsum("ek,eak->ea", sig[:, i], geom.grads)
        weak[:, i] = np.bincount(mesh_g.tets.ravel(), contrib.ravel(), minlength=mesh_g.n_nodes)
    f = eigenstress_load(geom, mesh_g.tets, mesh_g.n_nodes, a + b * mesh_g.points[:, 2])
    assert np.abs(f - weak).max() < 1e-10 * np.abs(weak).max()
