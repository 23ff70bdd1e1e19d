"""The edge form of the P1 stiffness equals the full assembly, and drops only exact zeros."""

from __future__ import annotations

import numpy as np

from diathermy.fem.edges import edge_stiffness, laplacian_pattern
from diathermy.fem.geometry import element_geometry
from diathermy.fem.scalar import assemble_diffusion
from diathermy.fem.sparsity import build_pattern


def test_edge_laplacian_equals_full_assembly(small_mesh, rng):
    geom = element_geometry(small_mesh.points, small_mesh.tets)
    n = small_mesh.n_nodes
    coeff = rng.uniform(0.1, 2.0, small_mesh.n_tets)
    K = assemble_diffusion(build_pattern(small_mesh.tets, n), geom, coeff).toarray()
    stiff = edge_stiffness(geom, small_mesh.tets, n)
    w = stiff.weights(coeff)
    pattern = laplacian_pattern(stiff)
    A = pattern.matrix(stiff, w).toarray()
    assert np.allclose(A, K, rtol=0, atol=1e-12 * np.abs(K).max())
    u = rng.normal(size=n)
    assert np.allclose(stiff.apply(w, u), K @ u, rtol=0, atol=1e-12 * np.abs(K @ u).max())
    assert np.allclose(stiff.degree(w), np.diag(K))


def test_kuhn_mesh_gives_seven_point_stencil(small_mesh):
    """Only axis-parallel edges couple: 3 per interior node, the 7-point stencil."""
    geom = element_geometry(small_mesh.points, small_mesh.tets)
    stiff = edge_stiffness(geom, small_mesh.tets, small_mesh.n_nodes)
    d = small_mesh.points[stiff.edges[:, 1]] - small_mesh.points[stiff.edges[:, 0]]
    assert np.all(np.count_nonzero(np.abs(d) > 1e-12, axis=1) == 1)
    nz, ny, nx = small_mesh.grid.shape
    assert stiff.n_edges == (nx - 1) * ny * nz + nx * (ny - 1) * nz + nx * ny * (nz - 1)
    assert np.all(stiff.weights(1.0) > 0)  # an M-matrix


def test_restricted_pattern_is_the_submatrix(small_mesh, rng):
    geom = element_geometry(small_mesh.points, small_mesh.tets)
    n = small_mesh.n_nodes
    stiff = edge_stiffness(geom, small_mesh.tets, n)
    w = stiff.weights(rng.uniform(0.5, 1.5, small_mesh.n_tets))
    full = laplacian_pattern(stiff).matrix(stiff, w).toarray()
    keep = np.sort(rng.choice(n, n // 2, replace=False))
    shift = rng.uniform(0, 1, keep.size)
    sub = laplacian_pattern(stiff, keep).matrix(stiff, w, shift).toarray()
    assert np.allclose(sub, full[np.ix_(keep, keep)] + np.diag(shift))
