"""Every vectorised kernel equals a slow, obviously correct element loop (its reference twin)."""

from __future__ import annotations

import numpy as np
import pytest

from diathermy.fem.geometry import element_geometry, gradient, structured_geometry
from diathermy.fem.scalar import (
    assemble_diffusion,
    assemble_mass,
    assemble_robin,
    lumped_mass,
    surface_load,
    triangle_areas,
    volume_load,
)
from diathermy.fem.sparsity import build_pattern


def reference_geometry(points, tet):
    """Gradients by solving for the affine shape functions of one tet."""
    A = np.column_stack([np.ones(4), points[tet]])  # N_a = c0 + c . x
    C = np.linalg.inv(A)  # columns: coefficients of each shape function
    return C[1:, :].T, abs(np.linalg.det(A)) / 6.0


def reference_diffusion(points, tets, coeff, n):
    K = np.zeros((n, n))
    for e, tet in enumerate(tets):
        G, vol = reference_geometry(points, tet)
        K[np.ix_(tet, tet)] += coeff[e] * vol * G @ G.T
    return K


def reference_mass(points, tets, coeff, n):
    """Consistent mass by 4-point (degree 2, exact for N_a N_b) quadrature."""
    a, b = 0.5854101966249685, 0.1381966011250105
    qp = np.full((4, 4), b) + np.eye(4) * (a - b)
    M = np.zeros((n, n))
    for e, tet in enumerate(tets):
        _, vol = reference_geometry(points, tet)
        for lam in qp:
            M[np.ix_(tet, tet)] += coeff[e] * vol / 4 * np.outer(lam, lam)
    return M


def test_structured_geometry_equals_generic(small_mesh):
    gen = element_geometry(small_mesh.points, small_mesh.tets)
    fast = structured_geometry(small_mesh.points, small_mesh.tets, small_mesh.shape_id)
    assert np.allclose(gen.grads, fast.grads, rtol=1e-12, atol=1e-12 * np.abs(gen.grads).max())
    assert np.allclose(gen.volumes, fast.volumes, rtol=1e-12, atol=0)


def test_geometry_and_gradient(small_mesh, rng):
    geom = element_geometry(small_mesh.points, small_mesh.tets)
    for e in rng.choice(small_mesh.n_tets, 20, replace=False):
        G, vol = reference_geometry(small_mesh.points, small_mesh.tets[e])
        assert np.allclose(geom.grads[e], G) and geom.volumes[e] == pytest.approx(vol)
    c = np.array([2.0, -3.0, 0.5])
    u = small_mesh.points @ c + 7.0
    assert np.allclose(gradient(geom, small_mesh.tets, u), c)


def test_diffusion_matches_reference(small_mesh, rng):
    geom = element_geometry(small_mesh.points, small_mesh.tets)
    coeff = rng.uniform(0.1, 2.0, small_mesh.n_tets)
    pattern = build_pattern(small_mesh.tets, small_mesh.n_nodes)
    K = assemble_diffusion(pattern, geom, coeff).toarray()
    assert np.allclose(
        K, reference_diffusion(small_mesh.points, small_mesh.tets, coeff, small_mesh.n_nodes)
    )


def test_mass_consistent_and_lumped(small_mesh, rng):
    geom = element_geometry(small_mesh.points, small_mesh.tets)
    coeff = rng.uniform(0.5, 2.0, small_mesh.n_tets)
    pattern = build_pattern(small_mesh.tets, small_mesh.n_nodes)
    M = assemble_mass(pattern, geom, coeff).toarray()
    ref = reference_mass(small_mesh.points, small_mesh.tets, coeff, small_mesh.n_nodes)
    assert np.allclose(M, ref)
    assert np.allclose(
        lumped_mass(geom, small_mesh.tets, small_mesh.n_nodes, coeff), ref.sum(axis=1)
    )


def test_robin_and_surface_load(small_mesh, rng):
    tris = small_mesh.boundary_faces["z+"]
    n = small_mesh.n_nodes
    h = rng.uniform(1.0, 30.0, tris.shape[0])
    full = assemble_robin(small_mesh.points, tris, n, h, lumped=False).toarray()
    ref = np.zeros((n, n))
    areas = triangle_areas(small_mesh.points, tris)
    for f, tri in enumerate(tris):
        ref[np.ix_(tri, tri)] += h[f] * areas[f] / 12 * (np.ones((3, 3)) + np.eye(3))
    assert np.allclose(full, ref)
    lumped = assemble_robin(small_mesh.points, tris, n, h).toarray()
    assert (
        np.allclose(np.diag(lumped), ref.sum(axis=1))
        and np.count_nonzero(lumped - np.diag(np.diag(lumped))) == 0
    )
    load = surface_load(small_mesh.points, tris, n, h)
    assert load.sum() == pytest.approx((h * areas).sum())
    assert np.allclose(load, full @ np.ones(n))


def test_volume_load_integrates_source(small_mesh, rng):
    geom = element_geometry(small_mesh.points, small_mesh.tets)
    q = rng.uniform(0, 1e6, small_mesh.n_tets)
    f = volume_load(geom, small_mesh.tets, small_mesh.n_nodes, q)
    assert f.sum() == pytest.approx((q * geom.volumes).sum(), rel=1e-12)
