"""Strain-energy density against an element loop, and the error metric's edge cases."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from diathermy.fem.geometry import element_geometry
from diathermy.mesh.grid import Grid
from diathermy.mesh.tet_mesh import build_tet_mesh
from diathermy.physics.strain_energy import (
    kuhn_strain_energy_density,
    relative_strain_energy_error,
    strain_energy_density,
)

E, NU = 0.27e6, 0.4


def reference_density(points, tets, u, E, nu):
    """1/2 eps : C : eps from the Voigt form, one tet at a time."""
    out = np.empty(len(tets))
    for e, tet in enumerate(tets):
        lam, mu = E[e] * nu / ((1 + nu) * (1 - 2 * nu)), E[e] / (2 * (1 + nu))
        D = lam * np.outer([1, 1, 1, 0, 0, 0], [1] * 3 + [0] * 3) + mu * np.diag([2] * 3 + [1] * 3)
        A = np.column_stack([np.ones(4), points[tet]])
        G = np.linalg.inv(A)[1:, :].T
        H = u[tet].T @ G  # du_i/dx_k
        v = [H[0, 0], H[1, 1], H[2, 2], H[0, 1] + H[1, 0], H[1, 2] + H[2, 1], H[0, 2] + H[2, 0]]
        out[e] = 0.5 * np.dot(v, D @ v)
    return out


def test_density_matches_reference(small_mesh, rng):
    geom = element_geometry(small_mesh.points, small_mesh.tets)
    u = rng.normal(scale=1e-4, size=(small_mesh.n_nodes, 3))
    Ee = rng.uniform(0.5, 2.0, small_mesh.n_tets) * E
    W = strain_energy_density(geom.grads, small_mesh.tets, u, Ee, NU)
    assert np.allclose(W, reference_density(small_mesh.points, small_mesh.tets, u, Ee, NU))
    assert np.all(W >= 0)


def test_kuhn_density_matches_reference_on_uniform_and_graded_grids(small_mesh, rng):
    """The node-difference kernel the engine uses gives every tet's W of the element loop."""
    graded = build_tet_mesh(
        Grid.from_axes(
            [0.0, 0.4e-3, 1e-3, 3e-3, 7e-3],
            [0.0, 2e-3, 2.5e-3, 6e-3],
            [0.0, 5e-3, 6e-3, 6.4e-3, 6.5e-3],
        )
    )
    for mesh in (small_mesh, graded):
        u = rng.normal(scale=1e-4, size=(mesh.n_nodes, 3))
        Ee = rng.uniform(0.5, 2.0, mesh.n_tets) * E
        W = kuhn_strain_energy_density(u, mesh.grid, Ee, NU)
        ref = reference_density(mesh.points, mesh.tets, u, Ee, NU)
        assert np.allclose(W, ref, rtol=1e-10, atol=1e-12 * ref.max())
        one = kuhn_strain_energy_density(u, mesh.grid, E, NU)  # one modulus for all
        assert np.allclose(
            one, reference_density(mesh.points, mesh.tets, u, np.full(mesh.n_tets, E), NU)
        )


def test_free_swelling_stores_dp2_over_2K(small_mesh):
    geom = element_geometry(small_mesh.points, small_mesh.tets)
    dp, K = 2e4, E / (3 * (1 - 2 * NU))
    u = dp / (3 * K) * (small_mesh.points - small_mesh.points.mean(axis=0))
    W = strain_energy_density(geom.grads, small_mesh.tets, u, E, NU)
    assert np.allclose(W, dp**2 / (2 * K), rtol=1e-12)
    assert np.allclose(kuhn_strain_energy_density(u, small_mesh.grid, E, NU), dp**2 / (2 * K))
    rigid = np.cross([0.1, -0.3, 0.2], small_mesh.points) + [1e-3, 0, 0]  # small rotation
    assert np.abs(strain_energy_density(geom.grads, small_mesh.tets, rigid, E, NU)).max() < 1e-6
    assert np.abs(kuhn_strain_energy_density(rigid, small_mesh.grid, E, NU)).max() < 1e-6


def test_error_metric_values():
    W_ref = np.array([3.0, 4.0, 0.0])
    assert relative_strain_energy_error(W_ref, W_ref) == 0.0
    assert relative_strain_energy_error(np.zeros(3), W_ref) == pytest.approx(1.0)
    assert relative_strain_energy_error(W_ref * 1.1, W_ref) == pytest.approx(0.1)
    assert relative_strain_energy_error(W_ref + [0, 0, 5.0], W_ref) == pytest.approx(1.0)


def test_error_metric_edge_cases():
    zero = np.zeros(4)
    assert relative_strain_energy_error(zero, zero) == 0.0
    assert relative_strain_energy_error(zero + [0, 0, 0, 1e-30], zero) == float("inf")
    with pytest.raises(ValueError, match="shape"):
        relative_strain_energy_error(np.zeros(3), zero)
    with pytest.raises(ValueError, match="finite"):
        relative_strain_energy_error(np.array([np.nan, 0, 0, 0]), zero + 1.0)
    assert relative_strain_energy_error(np.zeros(0), np.zeros(0)) == 0.0


@given(
    arrays(np.float64, 16, elements=st.floats(0, 1e6)),
    arrays(np.float64, 16, elements=st.floats(1e-3, 1e6)),
    st.floats(1e-6, 1e6),
)
def test_error_metric_properties(W, W_ref, scale):
    err = relative_strain_energy_error(W, W_ref)
    assert err >= 0 and np.isfinite(err)
    assert relative_strain_energy_error(W * scale, W_ref * scale) == pytest.approx(err, rel=1e-9)
