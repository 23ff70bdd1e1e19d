"""Level-set advance and re-initialisation against exact fronts (PHYSICS.md 6g) and a slow twin."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.ndimage as ndi
from hypothesis import given, settings
from hypothesis import strategies as st

from diathermy.errors import SolverDivergedError
from diathermy.mesh import Grid, build_tet_mesh
from diathermy.physics.levelset import (
    GHOST_SLOPE_CAP,
    _godunov_gradient,
    _stencil,
    advance,
    front_speed,
    initial_level_set,
    reinitialize,
    substeps_needed,
    tet_to_node,
    volume_incidence,
)
from diathermy.physics.topology import removed_fraction


def column_grid(n: int) -> Grid:
    """n nodes over 1 cm in z, a few columns wide: plane fronts are 1D."""
    return Grid((n, 4, 5), size_m=(0.004, 0.003, 0.01))


def down_crossings(phi: np.ndarray, z: np.ndarray) -> np.ndarray:
    """z of every crossing from phi > 0 (below) to phi <= 0 (above) along the z columns."""
    a, b = phi[:-1], phi[1:]
    s = a / np.where(a > b, a - b, 1.0)
    return (z[:-1, None, None] + s * (z[1] - z[0]))[(a > 0) & (b <= 0)]


def sphere_radii(phi: np.ndarray, grid: Grid, c: np.ndarray) -> np.ndarray:
    """Distance to c of every zero crossing of phi along the z columns."""
    x, y, z = grid.axes()
    a, b = phi[:-1], phi[1:]
    cross = (a < 0) != (b < 0)
    s = a / np.where(cross, a - b, 1.0)
    zc = z[:-1, None, None] + s * (z[1] - z[0])
    X, Y = np.meshgrid(x, y, indexing="xy")
    X, Y = np.broadcast_to(X, a.shape), np.broadcast_to(Y, a.shape)
    return np.sqrt((X[cross] - c[0]) ** 2 + (Y[cross] - c[1]) ** 2 + (zc[cross] - c[2]) ** 2)


def order(errors: list[float], hs: list[float]) -> list[float]:
    return [
        float(np.log(errors[i] / errors[i + 1]) / np.log(hs[i] / hs[i + 1]))
        for i in range(len(hs) - 1)
    ]


def reference_step(phi: np.ndarray, F: np.ndarray, spacing, dt: float) -> np.ndarray:
    """One forward-Euler Godunov step, node by node, with linearly extrapolated ghost nodes
    (slope capped at GHOST_SLOPE_CAP)."""
    h = (spacing[2], spacing[1], spacing[0])
    out = phi.copy()
    for idx in np.ndindex(phi.shape):
        g2 = 0.0
        for ax in range(3):
            n = phi.shape[ax]
            e = np.zeros(3, dtype=int)
            e[ax] = 1
            c = phi[idx]
            left = (
                phi[tuple(np.array(idx) - e)]
                if idx[ax] > 0
                else 2 * c - phi[tuple(np.array(idx) + e)]
            )
            right = (
                phi[tuple(np.array(idx) + e)]
                if idx[ax] < n - 1
                else 2 * c - phi[tuple(np.array(idx) - e)]
            )
            dm, dp = (c - left) / h[ax], (right - c) / h[ax]
            if idx[ax] == 0:  # the ghost's slope is capped at a distance's
                dm = min(dm, GHOST_SLOPE_CAP)
            if idx[ax] == n - 1:
                dp = max(dp, -GHOST_SLOPE_CAP)
            g2 += max(dm, 0.0, -dp) ** 2
        out[idx] = phi[idx] - dt * F[idx] * np.sqrt(g2)
    return out


def ghost_padded(phi: np.ndarray) -> np.ndarray:
    return np.pad(phi, 1, mode="reflect", reflect_type="odd")  # ghost = 2 phi_face - phi_inner


def test_initial_level_set_is_the_distance_to_the_top():
    g = Grid((5, 3, 4), size_m=(0.02, 0.01, 0.04), origin_m=(0.0, 0.0, -0.01))
    phi = initial_level_set(g)
    assert phi.shape == g.shape
    assert np.all(phi[-1] == 0.0) and np.allclose(phi[:, 1, 2], 0.03 - np.linspace(-0.01, 0.03, 5))


def test_front_speed_law():
    W = np.array([0.0, 0.7e5, 1.4e5, 2.1e5])
    F = front_speed(W, 0.7e5)
    assert np.allclose(F, [0.0, 0.0, 5e-3, 1e-2])
    assert np.allclose(front_speed(W, 0.7e5, v0=1.0), [0, 0, 1, 2])
    with pytest.raises(ValueError):
        front_speed(W, 0.0)


def test_tet_to_node_is_the_volume_weighted_mean(small_mesh, rng):
    from diathermy.fem.geometry import element_geometry

    mesh = small_mesh
    vol = element_geometry(mesh.points, mesh.tets).volumes
    w = rng.random(mesh.n_tets)
    include = rng.random(mesh.n_tets) > 0.3
    got = tet_to_node(w, mesh.tets, vol, mesh.n_nodes)
    got_in = tet_to_node(w, mesh.tets, vol, mesh.n_nodes, include=include)
    for node in rng.choice(mesh.n_nodes, 15, replace=False):
        around = np.flatnonzero((mesh.tets == node).any(axis=1))
        assert got[node] == pytest.approx(np.average(w[around], weights=vol[around]), rel=1e-12)
        kept = around[include[around]]
        want = np.average(w[kept], weights=vol[kept]) if kept.size else 0.0
        assert got_in[node] == pytest.approx(want, rel=1e-12)
    const = tet_to_node(np.full(mesh.n_tets, 3.0), mesh.tets, vol, mesh.n_nodes)
    assert np.allclose(const, 3.0)
    A = volume_incidence(mesh.tets, vol, mesh.n_nodes)
    for inc in (None, include):
        fast = tet_to_node(w, mesh.tets, vol, mesh.n_nodes, include=inc, incidence=A)
        assert np.allclose(
            fast, tet_to_node(w, mesh.tets, vol, mesh.n_nodes, include=inc), rtol=1e-13
        )


def test_one_step_equals_the_node_by_node_twin(rng):
    phi = rng.normal(size=(4, 5, 6))
    F = rng.random((4, 5, 6)) * (rng.random((4, 5, 6)) > 0.3)
    spacing = (0.7, 1.3, 0.9)
    dt = 0.5 / (F.max() * sum(1 / h for h in spacing))
    step = advance(phi, F, spacing, dt)
    assert step.n_substeps == 1
    assert np.allclose(step.phi, reference_step(phi, F, spacing, dt), rtol=0, atol=1e-14)


def test_plane_moves_down_at_constant_speed():
    """phi0 = z0 - z (tissue below z0), constant F: the front is at z0 - F t, error O(h)."""
    F, t, z0 = 2e-3, 2.0, 0.008
    for n in (21, 41, 81):
        g = column_grid(n)
        z, h = g.axes()[2], g.spacing_m[2]
        for profile in (lambda d: d, lambda d: 0.002 * np.sinh(d / 0.002)):
            phi0 = np.broadcast_to(profile(z0 - z)[:, None, None], g.shape)
            step = advance(phi0, np.full(g.shape, F), g.spacing_m, t)
            err = np.abs(down_crossings(step.phi, z) - (z0 - F * t)).max()
            # exact for a linear phi; a curved profile (same zero set) errs by a small fraction of h
            assert err <= 0.05 * h


def test_sphere_grows_first_order():
    """phi0 = |x - c| - R0 (removed inside): R(t) = R0 + F t, error first order in h."""
    L, F = 0.02, 1e-3
    R0, t = 0.2 * L, 0.15 * L / F
    errors, hs = [], []
    for n in (21, 41, 81):
        g = Grid((n, n, n), size_m=(L, L, L))
        c = np.array([0.513, 0.479, 0.507]) * L
        r = np.linalg.norm(g.points().reshape(g.shape + (3,)) - c, axis=-1)
        speed = np.where(r < 0.35 * L + 3 * L / (n - 1), F, 0.0)  # F > 0 only where the front goes
        step = advance(r - R0, speed, g.spacing_m, t)
        errors.append(np.abs(sphere_radii(step.phi, g, c) - (R0 + F * t)).mean())
        hs.append(L / (n - 1))
    assert max(e / h for e, h in zip(errors, hs, strict=True)) < 0.5
    assert min(order(errors, hs)) >= 0.8, (errors, order(errors, hs))


def test_variable_speed_front():
    """F = a + b z, front moving down: dz_f/dt = -(a + b z_f), z_f = (z0 + a/b) e^(-b t) - a/b."""
    a, b, z0, t = 5e-4, 0.25, 0.008, 2.0
    exact = (z0 + a / b) * np.exp(-b * t) - a / b
    errors, hs = [], []
    for n in (81, 161, 321):
        g = column_grid(n)
        z = g.axes()[2]
        phi0 = np.broadcast_to((z0 - z)[:, None, None], g.shape)
        speed = np.broadcast_to((a + b * z)[:, None, None], g.shape)
        step = advance(phi0, speed, g.spacing_m, t)
        errors.append(np.abs(down_crossings(step.phi, z) - exact).max())
        hs.append(g.spacing_m[2])
    # measured: 0.050 h, 0.056 h, 0.059 h (orders 0.85, 0.92, tending to 1 on finer grids)
    assert max(e / h for e, h in zip(errors, hs, strict=True)) < 0.1
    assert order(errors, hs)[-1] >= 0.8, (errors, order(errors, hs))


def test_variable_speed_front_survives_reinitialisation_every_step():
    """The re-init rule does not bias the front (min(d, phi) everywhere drifts 0.5-0.9 h ahead)."""
    a, b, z0, t, n = 5e-4, 0.25, 0.008, 2.0, 81
    g = column_grid(n)
    z = g.axes()[2]
    phi = np.broadcast_to((z0 - z)[:, None, None], g.shape).copy()
    speed = np.broadcast_to((a + b * z)[:, None, None], g.shape)
    for _ in range(40):
        phi = reinitialize(advance(phi, speed, g.spacing_m, t / 40).phi, g.spacing_m)
    exact = (z0 + a / b) * np.exp(-b * t) - a / b
    assert np.abs(down_crossings(phi, z) - exact).max() < 0.1 * g.spacing_m[2]


def test_substeps_keep_a_step_100x_above_cfl_bounded():
    L, F, n = 0.02, 1e-3, 41
    g = Grid((n, n, n), size_m=(L, L, L))
    c = np.full(3, 0.5 * L)
    r = np.linalg.norm(g.points().reshape(g.shape + (3,)) - c, axis=-1)
    phi0, speed = r - 0.2 * L, np.full(g.shape, F)
    dt_cfl = 0.5 / (F * sum(1 / h for h in g.spacing_m))  # the largest stable sub-step
    dt = 99.5 * dt_cfl
    big = advance(phi0, speed, g.spacing_m, dt)
    assert big.n_substeps == 100
    small = phi0
    for _ in range(37):  # other sub-step sizes: 37 physical steps of 2.7 dt_cfl, 3 sub-steps each
        small = advance(small, speed, g.spacing_m, dt / 37).phi
    h = L / (n - 1)
    assert big.phi.min() >= phi0.min() and big.phi.max() <= phi0.max()
    near = np.abs(big.phi) < 3 * h
    assert np.abs(big.phi - small)[near].max() < 0.1 * h
    assert np.abs(sphere_radii(big.phi, g, c) - (0.2 * L + F * dt)).max() < h
    # the same step without sub-steps breaks the maximum principle by many cells
    st_ = _stencil(phi0.shape, np.arange(phi0.size))
    raw = phi0.ravel() - dt * F * _godunov_gradient(phi0.ravel(), st_, (h, h, h))
    assert raw.min() < phi0.min() - 5 * h


def test_a_face_node_ahead_of_the_interior_does_not_run_away():
    """F > 0 on the top layer only, a step of 57 sub-steps: the top falls by exactly F dt.

    The ghost's slope is capped at 1 (a distance's); uncapped, the top node fell by a factor
    (1 + dt_sub F / h) per sub-step (-1e81 m after one 1 s engine step).
    """
    g = column_grid(9)
    phi = initial_level_set(g)
    speed = np.zeros(g.shape)
    speed[-1] = 1e-3
    step = advance(phi, speed, g.spacing_m, 10.0)
    assert step.n_substeps > 50
    assert np.all(np.isfinite(step.phi))
    assert step.phi[-1] == pytest.approx(np.full(g.shape[1:], -1e-2), rel=1e-9)
    assert np.array_equal(step.phi[:-1], phi[:-1])


def test_zero_speed_changes_nothing():
    g = column_grid(9)
    phi = initial_level_set(g) + 0.1234567
    for speed, dt in ((np.zeros(g.shape), 10.0), (np.ones(g.shape), 0.0)):
        step = advance(phi, speed, g.spacing_m, dt)
        assert step.n_substeps == 0 and np.array_equal(step.phi, phi) and step.phi is not phi


def test_only_nodes_with_speed_change_and_the_top_recedes():
    g = Grid((11, 9, 9), size_m=(0.01, 0.01, 0.01))
    phi = initial_level_set(g)
    speed = np.zeros(g.shape)
    speed[-3:, 3:6, 3:6] = 1e-3
    step = advance(phi, speed, g.spacing_m, 1.0)
    assert step.n_active == 27
    assert np.array_equal(step.phi[speed == 0], phi[speed == 0])
    assert np.all(step.phi[speed > 0] < phi[speed > 0])
    assert step.phi[-1, 4, 4] == pytest.approx(-1e-3)  # the top itself moves in (inflow face)


def test_bad_speed_raises_clearly():
    g = column_grid(9)
    phi = initial_level_set(g)
    for bad in (np.nan, np.inf):
        speed = np.zeros(g.shape)
        speed[3, 1, 1] = bad
        with pytest.raises(SolverDivergedError, match="not finite"):
            advance(phi, speed, g.spacing_m, 0.03)
    with pytest.raises(SolverDivergedError, match="sub-steps"):
        advance(phi, np.full(g.shape, 1e6), g.spacing_m, 0.03)
    with pytest.raises(ValueError, match=">= 0"):
        advance(phi, np.full(g.shape, -1.0), g.spacing_m, 0.03)
    with pytest.raises(ValueError):
        advance(phi, np.zeros(7), g.spacing_m, 0.03)


def test_substeps_needed_respects_the_cfl():
    for dt in (1e-3, 0.03, 0.1, 7.0):
        n = substeps_needed(0.37, (1e-3, 2e-3, 3e-3), dt, 0.5)
        assert (dt / n) * 0.37 * (1e3 + 5e2 + 1e3 / 3) <= 0.5
        assert n == 1 or (dt / (n - 1)) * 0.37 * (1e3 + 5e2 + 1e3 / 3) > 0.5


cases = st.tuples(
    st.integers(0, 2**32 - 1),
    st.tuples(st.integers(2, 6), st.integers(2, 6), st.integers(2, 6)),
    st.floats(0.0, 0.8),  # fraction of nodes at rest
)


@settings(max_examples=60, deadline=None)
@given(cases, st.floats(0.0, 1.0))
def test_one_substep_is_monotone(case, courant):
    """Random phi and F >= 0, one sub-step: phi never rises, nor falls below its stencil's min."""
    seed, shape, rest = case
    rng = np.random.default_rng(seed)
    phi = rng.normal(size=shape) * rng.choice([1e-3, 1.0, 1e3])
    F = rng.random(shape) * (rng.random(shape) >= rest)
    spacing = tuple(rng.uniform(0.2, 2.0, 3))
    dt = 0.0 if F.max() == 0 else courant * 0.5 / (F.max() * sum(1 / h for h in spacing))
    new = advance(phi, F, spacing, dt).phi
    assert np.all(np.isfinite(new)) and np.all(new <= phi)
    p = ghost_padded(phi)
    nb = [p[1:-1, 1:-1, 1:-1]]
    for ax in range(3):
        for s in (0, 2):
            sl = [slice(1, -1)] * 3
            sl[ax] = slice(s, s + shape[ax])
            nb.append(p[tuple(sl)])
    assert np.all(new >= np.min(nb, axis=0) - 1e-12 * np.abs(phi).max())
    assert np.array_equal(new[F == 0], phi[F == 0])


@settings(max_examples=40, deadline=None)
@given(cases, st.floats(0.0, 20.0))
def test_any_step_keeps_the_maximum_principle(case, courant):
    """Any dt (sub-stepped), F = 0 on the faces: no new extrema, phi never rises, no NaN."""
    seed, shape, rest = case
    rng = np.random.default_rng(seed)
    phi = rng.normal(size=shape)
    F = rng.random(shape) * (rng.random(shape) >= rest)
    F[[0, -1]] = 0
    F[:, [0, -1]] = 0
    F[:, :, [0, -1]] = 0
    spacing = tuple(rng.uniform(0.2, 2.0, 3))
    dt = courant / max(F.max() * sum(1 / h for h in spacing), 1e-300)
    new = advance(phi, F, spacing, dt).phi
    assert np.all(np.isfinite(new)) and np.all(new <= phi)
    assert new.min() >= phi.min() and new.max() <= phi.max()
    assert np.array_equal(new[F == 0], phi[F == 0])


def sphere_field(n: int = 33, L: float = 0.02):
    g = Grid((n, n, n), size_m=(L, L, L))
    c = np.array([0.51, 0.47, 0.53]) * L
    d = np.linalg.norm(g.points().reshape(g.shape + (3,)) - c, axis=-1) - 0.25 * L
    return g, c, d


def test_reinitialize_restores_a_distance_and_keeps_the_zero_set():
    g, c, d = sphere_field()
    h = g.spacing_m[0]
    phi = np.where(d > 0, 2.5 * d, 0.4 * d)  # steep on the healthy side, shallow on the removed
    new = reinitialize(phi, g.spacing_m, band_cells=None)
    dev = np.abs(np.linalg.norm(np.gradient(new, h), axis=0) - 1)[np.abs(d) < 3 * h]
    # measured 0.031 mean, 0.082 at the 90th percentile (skfmm alone on the exact d: 0.011, 0.032)
    assert dev.mean() < 0.05 and np.percentile(dev, 90) < 0.12
    r_old, r_new = sphere_radii(phi, g, c), sphere_radii(new, g, c)
    assert r_old.shape == r_new.shape and np.abs(r_new - r_old).max() < 0.2 * h  # measured 0.13 h


def test_reinitialize_band_and_trivial_cases():
    g, _, d = sphere_field()
    h = g.spacing_m[0]
    phi = np.where(d > 0, 2.0 * d, 0.5 * d)
    new = reinitialize(phi, g.spacing_m, band_cells=3)
    far = np.abs(d) > 4 * h
    assert np.array_equal(new[far], phi[far])
    assert np.abs(new - d)[np.abs(d) < 2 * h].max() < 0.5 * h  # skfmm alone on d: 0.36 h
    top = initial_level_set(g)
    assert np.array_equal(reinitialize(top, g.spacing_m), top)
    # a strided view gives what its copy gives (skfmm itself misreads strided input)
    wide = np.repeat(phi, 2, axis=2)
    assert np.array_equal(
        reinitialize(wide[:, :, ::2], g.spacing_m, band_cells=3), new
    )  # no removed node: nothing to do


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.2, 5.0), st.floats(0.2, 5.0))
def test_reinitialize_is_irreversible(seed, k_healthy, k_removed):
    """Signs never change, phi never rises where it can move the cut, and no tet heals."""
    g, c, d = sphere_field(n=13)
    rng = np.random.default_rng(seed)
    wiggle = 1 + 0.3 * np.sin(g.points() @ rng.uniform(-2e3, 2e3, 3)).reshape(g.shape)
    phi = np.where(d > 0, k_healthy * d, k_removed * d) * wiggle
    phi[rng.random(g.shape) < 0.05] = 0.0
    new = reinitialize(phi, g.spacing_m, band_cells=None)
    assert np.array_equal(np.sign(new), np.sign(phi))
    deep = ndi.maximum_filter(phi, size=3, mode="nearest") < 0
    assert np.all(new[~deep] <= phi[~deep])
    tets = build_tet_mesh(g).tets
    assert np.all(removed_fraction(new, tets) >= removed_fraction(phi, tets) - 1e-12)
