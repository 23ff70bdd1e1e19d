"""The non-local cut driver: a weighted mean (constants kept, bounded by the field), the local law
as l -> 0, second-order convergence to the continuous Gaussian mean, cut tissue left out, and
a dissection step that moves less under a sharp W spike than the local law does."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from diathermy.fem.geometry import element_geometry
from diathermy.mesh import Grid, build_tet_mesh
from diathermy.physics.dissection import cut_driver, dissection_step
from diathermy.physics.levelset import initial_level_set, tet_to_node, volume_incidence
from diathermy.physics.levelset_law import LevelSetLaw
from diathermy.physics.nonlocal_average import (
    TRUNCATE,
    axis_kernels,
    kernel_weight,
    nonlocal_mean,
)


def graded() -> Grid:
    return Grid.graded(
        (0.004, 0.004, 0.006),
        (0.006, 0.006, 0.01),
        4e-4,
        growth=1.3,
        max_cell_m=2e-3,
        size_m=(0.01, 0.01, 0.01),
    )


def lumped_volumes(grid: Grid) -> np.ndarray:
    """Nodal volumes of a tensor grid: the product of the per-axis dual cell lengths (m^3)."""
    duals = []
    for a in grid.axes():
        h = np.diff(a)
        duals.append(0.5 * (np.concatenate([[0.0], h]) + np.concatenate([h, [0.0]])))
    dx, dy, dz = duals
    return (dz[:, None, None] * dy[None, :, None] * dx[None, None, :]).ravel()


def test_constant_is_kept_and_tiny_length_is_the_local_field(rng):
    g = graded()
    w = rng.random(g.n_nodes)
    v = rng.random(g.n_nodes)
    k = axis_kernels(g.axes(), 1e-3)
    assert np.allclose(nonlocal_mean(np.full(g.n_nodes, 7.0), w, g.shape, k), 7.0, rtol=1e-13)
    tiny = axis_kernels(g.axes(), 1e-6)  # far below the 0.4 mm cells
    assert np.allclose(nonlocal_mean(v, w, g.shape, tiny), v, rtol=1e-12)


def test_linear_field_is_exact_away_from_the_faces():
    """A symmetric kernel on a uniform grid reproduces a linear field where it is not cut off."""
    g = Grid((41, 41, 41), size_m=(0.01, 0.01, 0.01))
    x, y, z = (p for p in g.points().T)
    f = 3.0 + 2e3 * x - 1e3 * y + 5e2 * z
    length = 5e-4
    out = nonlocal_mean(f, lumped_volumes(g), g.shape, axis_kernels(g.axes(), length))
    far = TRUNCATE * length + 1.25e-4  # the reach plus half a cell: no face node within it
    inner = np.all([(c > far) & (c < 0.01 - far) for c in (x, y, z)], axis=0)
    assert inner.sum() > 1000
    assert np.allclose(out[inner], f[inner], rtol=1e-12)


def truncated_gaussian_factor(k: float, length: float) -> float:
    """The exact normalised mean of cos(k s) about s = 0 under the 1-D kernel."""
    reach = TRUNCATE * length
    w = lambda s: float(kernel_weight(s, length))  # noqa: E731
    num = quad(lambda s: w(s) * np.cos(k * s), -reach, reach)[0]
    return num / quad(w, -reach, reach)[0]


def test_converges_at_second_order_to_the_continuous_mean():
    """cos(k x) cos(k y) cos(k z): the mean is the field times the 1-D factor cubed (periodic-free
    check on interior nodes), and the error falls as h^2 with the trapezoid weights."""
    length, k, L = 5e-4, 2 * np.pi / 4e-3, 0.008
    factor = truncated_gaussian_factor(k, length) ** 3
    errors = []
    for n in (17, 33, 65):
        g = Grid((n, n, n), size_m=(L, L, L))
        x, y, z = g.points().T
        f = np.cos(k * x) * np.cos(k * y) * np.cos(k * z)
        out = nonlocal_mean(f, lumped_volumes(g), g.shape, axis_kernels(g.axes(), length))
        far = TRUNCATE * length + 0.5 * L / (n - 1)
        inner = np.all([(c > far) & (c < L - far) for c in (x, y, z)], axis=0)
        errors.append(np.abs(out[inner] - factor * f[inner]).max())
    orders = np.log2(np.asarray(errors[:-1]) / np.asarray(errors[1:]))
    assert errors[-1] < 1e-3
    assert np.all(orders > 1.8), (errors, orders)


@settings(max_examples=40, deadline=None)
@given(
    length=st.floats(1e-5, 5e-3),
    seed=st.integers(0, 2**31 - 1),
    zero_share=st.floats(0.0, 0.95),
)
def test_mean_is_bounded_by_the_weighted_values(length, seed, zero_share):
    g = Grid((6, 7, 9), size_m=(0.004, 0.003, 0.002))
    rng = np.random.default_rng(seed)
    v = rng.normal(size=g.n_nodes) * 1e5
    w = rng.random(g.n_nodes) * (rng.random(g.n_nodes) > zero_share)
    out = nonlocal_mean(v, w, g.shape, axis_kernels(g.axes(), length))
    assert np.all(np.isfinite(out))
    if w.any():
        live = v[w > 0]
        got = out[out != 0.0]
        assert np.all(got >= live.min() - 1e-9 * abs(live).max())
        assert np.all(got <= live.max() + 1e-9 * abs(live).max())


@pytest.mark.parametrize("bad", [0.0, -1e-3, np.nan, np.inf])
def test_bad_length_is_refused(bad):
    with pytest.raises(ValueError, match="non-local length"):
        axis_kernels(Grid((3, 3, 3)).axes(), bad)


def spike_setup():
    g = Grid((21, 21, 21), size_m=(0.004, 0.004, 0.004))
    mesh = build_tet_mesh(g)
    vol = element_geometry(mesh.points, mesh.tets).volumes
    centroid = mesh.points[mesh.tets].mean(axis=1)
    top = np.array([0.002, 0.002, 0.004])
    W = np.where(np.linalg.norm(centroid - top, axis=1) < 3e-4, 20 * 7e4, 0.0)
    return g, mesh, vol, W


def test_cut_tissue_does_not_feed_the_mean():
    """W put on removed tets changes nothing; with l = 0 the driver is the local projection."""
    g, mesh, vol, W = spike_setup()
    removed = W > 0
    inc = volume_incidence(mesh.tets, vol, mesh.n_nodes)
    kw = dict(mesh=mesh, grid=g, volumes=vol, incidence=inc)
    a = cut_driver(np.zeros_like(W), removed, length_m=5e-4, **kw)
    b = cut_driver(W, removed, length_m=5e-4, **kw)
    assert np.array_equal(a, b) and not b.any()
    local = cut_driver(W, np.zeros_like(removed), length_m=0.0, **kw)
    assert np.array_equal(local, tet_to_node(W, mesh.tets, vol, mesh.n_nodes))
    no_inc = dict(kw, incidence=None)
    assert np.allclose(
        cut_driver(W, ~removed, length_m=5e-4, **no_inc),
        cut_driver(W, ~removed, length_m=5e-4, **kw),
        rtol=1e-12,
    )


def test_a_sharp_spike_cuts_less_under_the_nonlocal_driver():
    """A 0.3 mm spike of 20 kappa: the local law cuts into it, the 0.5 mm mean dilutes it below
    kappa (its volume share within the kernel is small) and nothing is cut."""
    g, mesh, vol, W = spike_setup()
    inc = volume_incidence(mesh.tets, vol, mesh.n_nodes)
    phi = initial_level_set(g)
    removed = np.zeros(mesh.n_tets, dtype=bool)
    cut = {}
    for length in (0.0, 5e-4):
        law = LevelSetLaw(5e-3, 7e4, 0.5, 10, nonlocal_length_m=length)
        res = dissection_step(
            phi,
            W,
            removed,
            mesh=mesh,
            grid=g,
            volumes=vol,
            incidence=inc,
            law=law,
            dt=0.03,
            steps_since_reinit=0,
            previous=None,
        )
        cut[length] = float(vol[res.removed].sum())
    assert cut[0.0] > 0.0
    assert cut[5e-4] < 0.5 * cut[0.0]
