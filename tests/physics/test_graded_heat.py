"""The heat step on graded grids: the convective semi-infinite solid (PHYSICS.md 6b) on a column
fine at the surface, and the energy balance of an electrode-heated block."""

from __future__ import annotations

import numpy as np
import pytest

from diathermy.fem.edges import edge_stiffness
from diathermy.fem.geometry import structured_geometry
from diathermy.mesh import Grid, build_tet_mesh
from diathermy.mesh.grading import graded_axis
from diathermy.physics.contact_load import contact_weights
from diathermy.physics.driven_potential import DrivenPotential, ElectrodeDrive
from diathermy.physics.electric import PotentialSolver, joule_heat
from diathermy.physics.heat_operator import heat_mesh
from diathermy.physics.thermal import HeatStepper
from tests.physics.convective_column import T_INF_K, T_INITIAL_K, column_max_error

K_TISSUE, RHO_C, T_AMB, T0, SIGMA = 0.574, 1019.8 * 3441.0, 298.15, 310.15, 0.33


def test_semi_infinite_solid_on_a_column_graded_toward_the_surface():
    """erfc(xi) - exp(-xi^2) erfcx(xi + beta) at t = 60 s: a 30 mm column with 0.25 mm cells in
    the top 3 mm growing by 1.15 to <= 2 mm below (35 nodes); within 0.2 % of T_inf - Ti
    (measured 0.092 %; the uniform 0.25 mm column: 0.022 % with 121 nodes)."""
    z = graded_axis(0.0, 0.03, (0.027, 0.03), 2.5e-4, 1.15, max_cell=2e-3)
    mesh = build_tet_mesh(Grid.from_axes([0.0, 1e-3], [0.0, 1e-3], z))
    assert mesh.grid.nz < 121  # the uniform test needs 121 nodes at 0.25 mm
    geom = structured_geometry(mesh.points, mesh.tets, mesh.shape_id)
    hm = heat_mesh(mesh, geom, edge_stiffness(geom, mesh.tets, mesh.n_nodes))
    err = column_max_error(mesh, hm, k=K_TISSUE, rho_c=RHO_C)
    assert err < 2e-3 * (T_INF_K - T_INITIAL_K)


def test_electrode_heated_graded_block_balances_its_energy():
    """Joule energy in = delivered power x dt exactly; stored = Joule - convective loss."""
    g = Grid.graded(
        (0.097, 0.047, 0.097), (0.103, 0.053, 0.1), 1e-3, growth=1.25, max_cell_m=6.25e-3
    )
    mesh = build_tet_mesh(g)
    geom = structured_geometry(mesh.points, mesh.tets, mesh.shape_id)
    stiff = edge_stiffness(geom, mesh.tets, mesh.n_nodes)
    sol = DrivenPotential(PotentialSolver(mesh, stiff)).solve(
        SIGMA, contact_weights(mesh, (0.1, 0.05, 0.1), 1.17e-3), ElectrodeDrive()
    )
    q = joule_heat(mesh.grid, np.full(mesh.n_tets, SIGMA), sol.V)
    stepper = HeatStepper(heat_mesh(mesh, geom, stiff), h_w_per_m2_k=25.0, t_ambient_k=T_AMB)
    T = np.full(mesh.n_nodes, T0)
    for _ in range(5):
        res = stepper.step(T, 0.03, rho_c=RHO_C, k=K_TISSUE, q=q)
        e = res.energy
        assert e.joule_j == pytest.approx(0.03 * sol.power_w, rel=1e-7)
        scale = abs(e.stored_j) + e.joule_j + abs(e.convective_loss_j)
        assert abs(e.imbalance_j) < 1e-7 * scale  # the solve's tolerance (measured 6e-9)
        T = res.T
    assert T.max() > T0 + 5.0 and T.min() >= T_AMB - 1e-9
