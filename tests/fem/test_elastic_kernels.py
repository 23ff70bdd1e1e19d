"""The vectorised elasticity kernels equal slow element loops (their reference twins)."""

from __future__ import annotations

import numpy as np
import pytest

from diathermy.fem.elastic import (
    eigenstress_load,
    elastic_assembler,
    elastic_local,
    rigid_body_modes,
    strain,
)
from diathermy.fem.geometry import element_geometry, structured_geometry
from diathermy.fem.sparsity import build_pattern

NU = 0.4


def reference_element(points, tet, E, nu):
    """B^T D B |T| with the 6x12 Voigt strain matrix, affine shape functions by inversion."""
    A = np.column_stack([np.ones(4), points[tet]])
    G = np.linalg.inv(A)[1:, :].T  # (4, 3) gradients
    vol = abs(np.linalg.det(A)) / 6.0
    B = np.zeros((6, 12))
    for a in range(4):
        gx, gy, gz = G[a]
        B[:, 3 * a : 3 * a + 3] = [
            [gx, 0, 0], [0, gy, 0], [0, 0, gz], [gy, gx, 0], [0, gz, gy], [gz, 0, gx],
        ]  # fmt: skip
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    D = lam * np.outer([1, 1, 1, 0, 0, 0], [1, 1, 1, 0, 0, 0]) + mu * np.diag([2, 2, 2, 1, 1, 1])
    return vol * B.T @ D @ B, G, vol


def reference_stiffness(points, tets, E, nu, n):
    K = np.zeros((3 * n, 3 * n))
    for e, tet in enumerate(tets):
        Ke, _, _ = reference_element(points, tet, E[e], nu)
        dofs = (3 * tet[:, None] + np.arange(3)).ravel()
        K[np.ix_(dofs, dofs)] += Ke
    return K


@pytest.fixture(scope="module")
def parts(small_mesh):
    pattern = build_pattern(small_mesh.tets, small_mesh.n_nodes)
    geom = element_geometry(small_mesh.points, small_mesh.tets)
    return pattern, geom


def test_local_matrix_matches_voigt_reference(small_mesh, parts, rng):
    _, geom = parts
    E = rng.uniform(1e3, 1e6, small_mesh.n_tets)
    K = elastic_local(geom, E, NU)
    for e in rng.choice(small_mesh.n_tets, 10, replace=False):
        Ke, _, _ = reference_element(small_mesh.points, small_mesh.tets[e], E[e], NU)
        ours = K[e].transpose(0, 2, 1, 3).reshape(12, 12)
        assert np.allclose(ours, Ke, rtol=1e-12, atol=1e-12 * np.abs(Ke).max())


@pytest.mark.parametrize("structured", [False, True])
def test_assembly_matches_element_loop(small_mesh, parts, rng, structured):
    pattern, geom = parts
    E = rng.uniform(0.1, 2.0, small_mesh.n_tets) * 0.27e6
    if structured:
        geom = structured_geometry(small_mesh.points, small_mesh.tets, small_mesh.shape_id)
        asm = elastic_assembler(pattern, geom, small_mesh.shape_id)
    else:
        asm = elastic_assembler(pattern, geom)
    K = asm.stiffness(E, NU)
    assert K.blocksize == (3, 3)
    ref = reference_stiffness(small_mesh.points, small_mesh.tets, E, NU, small_mesh.n_nodes)
    assert np.allclose(K.toarray(), ref, rtol=1e-11, atol=1e-11 * np.abs(ref).max())
    K2 = asm.stiffness(2.0 * E, NU)  # the gather buffer is reused: no stale values
    assert np.allclose(K2.toarray(), 2.0 * ref, rtol=1e-11, atol=1e-11 * np.abs(ref).max())


def test_stiffness_symmetric_psd_with_rigid_kernel(small_mesh, parts, rng):
    pattern, geom = parts
    E = rng.uniform(0.5, 2.0, small_mesh.n_tets)
    K = elastic_assembler(pattern, geom).stiffness(E, NU).toarray()
    assert np.allclose(K, K.T, atol=1e-12 * np.abs(K).max())
    B = rigid_body_modes(small_mesh.points)
    assert np.abs(K @ B).max() < 1e-9 * np.abs(K).max()
    w = np.linalg.eigvalsh(K)
    assert np.sum(w < 1e-9 * w.max()) == 6  # exactly the rigid modes are free
    assert w.min() > -1e-9 * w.max()


def test_eigenstress_load_matches_reference_and_is_self_equilibrated(small_mesh, parts, rng):
    _, geom = parts
    n = small_mesh.n_nodes
    dp = rng.uniform(-1e4, 5e5, n)
    weight = (rng.random(small_mesh.n_tets) > 0.3).astype(float)
    f = eigenstress_load(geom, small_mesh.tets, n, dp, weight)
    ref = np.zeros((n, 3))
    for e, tet in enumerate(small_mesh.tets):
        _, G, vol = reference_element(small_mesh.points, tet, 1.0, NU)
        # int_T dp div(N_a e_i) with P1 dp: 4-point degree-2 rule (exact for linear dp).
        ref[tet] += weight[e] * vol * dp[tet].mean() * G
    assert np.allclose(f, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    B = rigid_body_modes(small_mesh.points)
    assert np.abs(B.T @ f.ravel()).max() < 1e-10 * np.abs(f).sum()  # no net force or moment
    hot = rng.random(n) < 0.05  # a pressure excess on a few nodes only: their tets' rows
    dp_hot = np.where(hot, dp, 0.0)
    touching = small_mesh.tets_touching(np.flatnonzero(hot))  # the engine's path
    local = eigenstress_load(geom, small_mesh.tets, n, dp_hot, weight, touching=touching)
    every = eigenstress_load(geom, small_mesh.tets, n, dp_hot, weight)
    assert np.allclose(local, every, rtol=1e-12, atol=1e-12 * np.abs(every).max())
    assert not np.any(
        local[~np.isin(np.arange(n), small_mesh.tets[np.any(hot[small_mesh.tets], axis=1)])]
    )


def test_strain_of_affine_field_is_exact(small_mesh, parts, rng):
    _, geom = parts
    G = rng.normal(size=(3, 3))
    u = small_mesh.points @ G.T + rng.normal(size=3)
    eps = strain(geom, small_mesh.tets, u)
    assert np.allclose(eps, 0.5 * (G + G.T))


def test_invalid_poisson_ratio(parts):
    _, geom = parts
    with pytest.raises(ValueError, match="Poisson"):
        elastic_local(geom, 1.0, 0.5)
