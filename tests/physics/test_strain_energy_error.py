"""The strain-energy error on a structured grid (the surrogate evaluation's metric)."""

from __future__ import annotations

import numpy as np

from diathermy.fem.geometry import structured_geometry
from diathermy.mesh import Grid, build_tet_mesh
from diathermy.physics.materials import Tissue
from diathermy.physics.strain_energy_error import strain_energy_error_on_grid, tet_youngs_modulus
from diathermy.physics.topology import evaluate_topology

GRID = (4, 5, 6)
SPACING = (0.01, 0.02, 0.015)


def _affine(G: np.ndarray) -> np.ndarray:
    """u = G x on the grid, (nz, ny, nx, 3)."""
    nz, ny, nx = GRID
    dx, dy, dz = SPACING
    z, y, x = np.meshgrid(np.arange(nz) * dz, np.arange(ny) * dy, np.arange(nx) * dx, indexing="ij")
    xyz = np.stack([x, y, z], axis=-1)
    return xyz @ G.T


def test_scaled_field_has_the_analytic_error() -> None:
    # W is quadratic in u: W(a u) = a^2 W(u), so the relative error of a*u is |a^2 - 1|
    err = strain_energy_error_on_grid(GRID, SPACING, {"youngs_modulus_pa": 1e5})
    u = _affine(np.array([[1e-3, 2e-4, 0], [0, -5e-4, 1e-4], [3e-4, 0, 2e-3]]))
    phi = np.ones(GRID)
    p = np.full(GRID, 101325.0)
    assert err(u, u, p, phi) == 0.0
    np.testing.assert_allclose(err(2 * u, u, p, phi), 3.0, rtol=1e-12)
    np.testing.assert_allclose(err(0.5 * u, u, p, phi), 0.75, rtol=1e-12)


def test_rigid_motion_has_no_energy() -> None:
    err = strain_energy_error_on_grid(GRID, SPACING)
    u_ref = _affine(np.diag([1e-3, 1e-3, 1e-3]))
    omega = np.array([[0, -1e-3, 2e-3], [1e-3, 0, -5e-4], [-2e-3, 5e-4, 0]])  # skew: rotation
    u = u_ref + _affine(omega) + 1e-3  # plus a translation
    np.testing.assert_allclose(err(u, u_ref, np.zeros(GRID), np.ones(GRID)), 0.0, atol=1e-10)


def test_cut_tets_take_the_ersatz_modulus_by_the_engines_rule() -> None:
    """E is ersatz exactly on the tets the engine removes (half the volume cut, or loose),
    which is not the mean-nodal-phi rule: a tet a third cut can have mean phi <= 0."""
    tissue = Tissue()
    mesh = build_tet_mesh(Grid((5, 5, 5), size_m=(0.01, 0.01, 0.01)))
    geom = structured_geometry(mesh.points, mesh.tets, mesh.shape_id)
    phi = np.random.default_rng(4).normal(size=mesh.n_nodes) + 0.3
    E = tet_youngs_modulus(phi, mesh, tissue)
    topo = evaluate_topology(phi, mesh, geom.volumes)
    engine_removed = topo.removed | topo.loose
    ersatz = tissue.ersatz_stiffness_ratio * tissue.youngs_modulus_pa
    np.testing.assert_array_equal(E, np.where(engine_removed, ersatz, tissue.youngs_modulus_pa))
    mean_rule_removed = phi[mesh.tets].mean(axis=1) <= 0
    assert engine_removed.any() and np.any(engine_removed != mean_rule_removed)
