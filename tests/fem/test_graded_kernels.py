"""The fast structured P1 kernels on graded grids against their slow per-element twins, and the
P1 convergence rates (PHYSICS.md 6h) on a graded mesh family."""

from __future__ import annotations

import numpy as np
import pyamg
import pytest

from diathermy.fem.edges import edge_stiffness, laplacian_pattern
from diathermy.fem.elastic import ElasticAssembler, elastic_assembler
from diathermy.fem.geometry import (
    element_geometry,
    gradient,
    structured_geometry,
)
from diathermy.fem.scalar import assemble_diffusion, volume_load, volume_load_matrix
from diathermy.fem.sparsity import build_pattern
from diathermy.mesh import Grid, TetMesh, build_tet_mesh
from diathermy.mesh.grading import graded_axis
from diathermy.mesh.kuhn_fields import axis_differences, shape_gradient, tet_mean


@pytest.fixture(scope="module")
def graded_mesh() -> TetMesh:
    g = Grid.graded(
        (0.01, 0.004, 0.006), (0.014, 0.006, 0.01), 1e-3, growth=1.6, size_m=(0.03, 0.01, 0.01)
    )
    return build_tet_mesh(g)


def test_graded_geometry_equals_element_loop(graded_mesh):
    m = graded_mesh
    slow = element_geometry(m.points, m.tets)
    fast = structured_geometry(m.points, m.tets, m.shape_id)
    assert np.allclose(fast.volumes, slow.volumes, rtol=1e-12, atol=0)
    scale = np.abs(slow.grads).max()
    assert np.allclose(fast.grads, slow.grads, rtol=1e-10, atol=1e-12 * scale)
    assert len(np.unique(np.round(fast.volumes, 20))) > 6  # really graded


@pytest.mark.parametrize("graded", [True, False])
def test_tet_operators_as_matrices_equal_their_element_formulas(graded, graded_mesh, small_mesh):
    """The gradient from node differences per Kuhn shape, the volume load and the tet mean as
    reusable sparse products give the element formulas' numbers."""
    m = graded_mesh if graded else small_mesh
    geom = structured_geometry(m.points, m.tets, m.shape_id)
    rng = np.random.default_rng(3)
    u, q = rng.standard_normal(m.n_nodes), rng.standard_normal(m.n_tets)
    ref = np.einsum("ea,eak->ek", u[m.tets], geom.grads)
    scale = np.abs(ref).max()
    diffs = axis_differences(u, m.grid)
    by_shape = np.stack([np.stack(shape_gradient(diffs, s), axis=-1) for s in range(6)], axis=3)
    assert np.allclose(by_shape.reshape(-1, 3), ref, rtol=0, atol=1e-13 * scale)
    assert np.allclose(gradient(geom, m.tets, u), ref, rtol=0, atol=1e-13 * scale)
    by_bincount = np.bincount(m.tets.ravel(), np.repeat(q * geom.volumes / 4, 4), m.n_nodes)
    load = volume_load_matrix(geom, m.tets, m.n_nodes) @ q
    assert np.allclose(load, by_bincount, rtol=0, atol=1e-14 * np.abs(by_bincount).max())
    assert np.allclose(volume_load(geom, m.tets, m.n_nodes, q), load, rtol=0, atol=0)
    mean = tet_mean(u, m.grid)
    assert np.allclose(mean, u[m.tets].mean(axis=1), rtol=0, atol=1e-15 * np.abs(u).max())


def test_uniform_geometry_is_bit_identical_to_the_translate_gather(small_mesh):
    m = small_mesh
    first = np.array([np.flatnonzero(m.shape_id == s)[0] for s in range(6)])
    ref = element_geometry(m.points, m.tets[first])
    fast = structured_geometry(m.points, m.tets, m.shape_id)
    assert np.array_equal(fast.grads, ref.grads[m.shape_id.astype(np.intp)])
    assert np.array_equal(fast.volumes, ref.volumes[m.shape_id.astype(np.intp)])


def test_graded_edge_laplacian_is_the_7_point_p1_stiffness(graded_mesh, rng):
    m = graded_mesh
    geom = structured_geometry(m.points, m.tets, m.shape_id)
    coeff = rng.uniform(0.1, 2.0, m.n_tets)
    stiff = edge_stiffness(geom, m.tets, m.n_nodes)
    g = m.grid
    axis_edges = (g.nx - 1) * g.ny * g.nz + g.nx * (g.ny - 1) * g.nz + g.nx * g.ny * (g.nz - 1)
    assert stiff.n_edges == axis_edges
    K_edges = laplacian_pattern(stiff).matrix(stiff, stiff.weights(coeff))
    K_full = assemble_diffusion(build_pattern(m.tets, m.n_nodes), geom, coeff)
    assert abs(K_edges - K_full).max() <= 1e-12 * abs(K_full).max()


def test_graded_elastic_assembly_equals_generic(graded_mesh, rng):
    m = graded_mesh
    geom = structured_geometry(m.points, m.tets, m.shape_id)
    pattern = build_pattern(m.tets, m.n_nodes)
    E = rng.uniform(1e3, 3e5, m.n_tets)
    fast = elastic_assembler(pattern, geom, m.shape_id)
    assert fast.cell_factors is not None
    slow = ElasticAssembler(pattern, element_geometry(m.points, m.tets))
    Kf, Ks = fast.stiffness(E, 0.4).tocsr(), slow.stiffness(E, 0.4).tocsr()
    assert abs(Kf - Ks).max() <= 1e-10 * abs(Ks).max()


@pytest.mark.parametrize("graded", [True, False])
def test_stiffness_blocks_are_stored_in_c_order(graded, graded_mesh, small_mesh):
    """scipy's BSR mat-vec copies a data array that is not C-contiguous on every call (a
    graded stiffness once came out transposed: K @ u 3x slower on the fixed-electrode grid)."""
    m = graded_mesh if graded else small_mesh
    geom = structured_geometry(m.points, m.tets, m.shape_id)
    fast = elastic_assembler(build_pattern(m.tets, m.n_nodes), geom, m.shape_id)
    E = np.full(m.n_tets, 3e4)
    assert fast.stiffness(E, 0.45).data.flags.c_contiguous
    assert fast.stiffness_blocks(E, 0.45, np.arange(5)).flags.c_contiguous


def test_uniform_elastic_assembly_keeps_the_single_product(small_mesh):
    m = small_mesh
    geom = structured_geometry(m.points, m.tets, m.shape_id)
    fast = elastic_assembler(build_pattern(m.tets, m.n_nodes), geom, m.shape_id)
    assert fast.cell_factors is None and fast.gather is not None


# --- P1 convergence on a graded family ---------------------------------------------------------


def _refined(axis: np.ndarray, times: int) -> np.ndarray:
    """Split every cell of ``axis`` in two, ``times`` times (the grading pattern is kept)."""
    for _ in range(times):
        mid = 0.5 * (axis[1:] + axis[:-1])
        axis = np.sort(np.concatenate([axis, mid]))
    return axis


def _manufactured_errors(level: int) -> tuple[float, float, float]:
    """-div grad u = f for u = sin(pi x) sin(pi y) sin(pi z) on a graded unit cube, u = 0 around."""
    base = graded_axis(0.0, 1.0, (0.35, 0.5), 0.1, 1.6)
    axes = [_refined(base, level)] * 3
    mesh = build_tet_mesh(Grid.from_axes(*axes))
    geom = structured_geometry(mesh.points, mesh.tets, mesh.shape_id)
    stiff = edge_stiffness(geom, mesh.tets, mesh.n_nodes)
    boundary = np.unique(mesh.surface_triangles())
    free = np.setdiff1d(np.arange(mesh.n_nodes), boundary)
    K = laplacian_pattern(stiff, free).matrix(stiff, stiff.weights(1.0))

    def u(p):
        return np.prod(np.sin(np.pi * p), axis=-1)

    qa, qb = 0.5854101966249685, 0.1381966011250105  # 4-point degree-2 rule
    lam = np.full((4, 4), qb) + np.eye(4) * (qa - qb)
    verts = mesh.points[mesh.tets]
    load = np.zeros(mesh.n_nodes)
    for row in lam:
        fq = 3 * np.pi**2 * u(np.einsum("a,eak->ek", row, verts)) * geom.volumes / 4
        load += np.bincount(mesh.tets.ravel(), (fq[:, None] * row).ravel(), minlength=mesh.n_nodes)
    uh = np.zeros(mesh.n_nodes)
    # AMG-preconditioned CG to a residual far below the discretisation error (a direct 3-D
    # solve of the finest level took ~10 s)
    ml = pyamg.smoothed_aggregation_solver(K.tocsr())
    uh[free] = ml.solve(load[free], tol=1e-12, accel="cg", maxiter=200)
    err2 = 0.0
    for row in lam:
        x = np.einsum("a,eak->ek", row, verts)
        err2 += np.sum(geom.volumes / 4 * (uh[mesh.tets] @ row - u(x)) ** 2)
    c = mesh.centroids()
    s, co = np.sin(np.pi * c), np.cos(np.pi * c)
    grad_u = np.pi * np.column_stack(
        [co[:, 0] * s[:, 1] * s[:, 2], s[:, 0] * co[:, 1] * s[:, 2], s[:, 0] * s[:, 1] * co[:, 2]]
    )
    grad_uh = np.einsum("ea,eak->ek", uh[mesh.tets], geom.grads)
    h1 = np.sum(geom.volumes * np.sum((grad_u - grad_uh) ** 2, axis=1))
    assert volume_load(geom, mesh.tets, mesh.n_nodes, np.ones(mesh.n_tets)).sum() == pytest.approx(
        1
    )
    return float(np.diff(axes[0]).max()), float(np.sqrt(err2)), float(np.sqrt(h1))


def test_p1_convergence_rates_on_a_graded_mesh():
    """L2 error O(h^2) (slope >= 1.8), energy error O(h) (slope >= 0.9); cells 0.1 .. 0.26 grow
    by up to 1.6 per cell and are halved per level."""
    hs, l2, h1 = np.array([_manufactured_errors(level) for level in (0, 1, 2)]).T
    l2_slopes = np.diff(np.log(l2)) / np.diff(np.log(hs))
    h1_slopes = np.diff(np.log(h1)) / np.diff(np.log(hs))
    assert np.all(l2_slopes >= 1.8), l2_slopes
    assert np.all(h1_slopes >= 0.9), h1_slopes
