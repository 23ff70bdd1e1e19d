"""Signed distance on graded (rectilinear) grids against exact distances of planes and a sphere,
with the measured order of accuracy, and clear errors for bad input."""

from __future__ import annotations

import numpy as np
import pytest
import skfmm
from hypothesis import given
from hypothesis import strategies as st

from diathermy.errors import MeshError
from diathermy.mesh.grading import graded_axis
from diathermy.physics.rectilinear_distance import godunov_update, signed_distance

BASE = (
    graded_axis(0.0, 1.0, (0.35, 0.6), 0.1, 1.6),
    graded_axis(0.0, 1.0, (0.3, 0.55), 0.1, 1.6),
    graded_axis(0.0, 1.0, (0.4, 0.7), 0.1, 1.6),
)


def refined(axis: np.ndarray, times: int) -> np.ndarray:
    """Split every cell in two ``times`` times: the grading pattern stays, every cell halves."""
    for _ in range(times):
        axis = np.sort(np.concatenate([axis, 0.5 * (axis[1:] + axis[:-1])]))
    return axis


def graded_nodes(level: int) -> tuple[tuple[np.ndarray, ...], np.ndarray, float]:
    axes = tuple(refined(a, level) for a in BASE)
    Z, Y, X = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    h = max(float(np.diff(a).max()) for a in axes)
    return axes, np.stack([X, Y, Z], axis=-1), h


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_axis_aligned_plane_is_exact_on_a_graded_grid(axis):
    axes, xyz, _ = graded_nodes(1)
    exact = xyz[..., axis] - 0.537
    d = signed_distance(5.0 * exact, axes)
    assert np.abs(d - exact).max() < 1e-12


def test_tilted_plane_exact_at_the_front_and_converging_away():
    """Exact on the start nodes; elsewhere (nodes whose foot on the plane lies in the block, so
    the in-block distance is the plane's) the error falls with h but slower than h, from the
    inflow faces (measured 0.05 h, 0.08 h, 0.11 h; scikit-fmm on a uniform grid does the same:
    2.2e-2 / 1.1e-2 / 5.5e-3 at h = 0.1 / 0.05 / 0.025, ours there 9.1e-3 / 6.5e-3 / 4.4e-3)."""
    n = np.array([0.3, 0.5, 0.81]) / np.linalg.norm([0.3, 0.5, 0.81])
    errs, hs = [], []
    for level in (0, 1, 2):
        axes, xyz, h = graded_nodes(level)
        exact = (xyz - np.array([0.45, 0.5, 0.52])) @ n
        d = signed_distance(3.0 * exact, axes)
        front = np.zeros(exact.shape, dtype=bool)  # nodes with a sign change to a neighbour
        for ax in range(3):
            s = np.sign(np.moveaxis(exact, ax, 0))
            f = np.moveaxis(front, ax, 0)
            f[:-1] |= s[:-1] != s[1:]
            f[1:] |= s[:-1] != s[1:]
        assert np.abs(d - exact)[front].max() < 1e-12
        assert np.all(np.sign(d) == np.sign(exact))
        foot = xyz - exact[..., None] * n
        inside = np.all((foot >= 0) & (foot <= 1), axis=-1)
        errs.append(np.abs(d - exact)[inside].max())
        hs.append(h)
    assert np.all(np.diff(errs) < 0) and np.all(np.array(errs) < 0.15 * np.array(hs)), errs


def test_sphere_converges_first_order_and_second_near_the_front():
    """|x - c| - R from phi = tanh(3 (|x - c| - R)): global max error O(h) (measured 0.90, 0.91),
    the band |d| < 2h O(h^2)-like (measured 1.46, 1.61)."""
    e_max, e_band, hs = [], [], []
    for level in (0, 1, 2):
        axes, xyz, h = graded_nodes(level)
        exact = np.linalg.norm(xyz - np.array([0.47, 0.5, 0.49]), axis=-1) - 0.2
        d = signed_distance(np.tanh(3.0 * exact), axes)
        err = np.abs(d - exact)
        e_max.append(err.max())
        e_band.append(err[np.abs(exact) < 2 * h].max())
        hs.append(h)
        assert np.all(np.sign(d) == np.sign(exact))
    order_max = np.diff(np.log(e_max)) / np.diff(np.log(hs))
    order_band = np.diff(np.log(e_band)) / np.diff(np.log(hs))
    assert np.all(order_max >= 0.8), order_max
    assert np.all(order_band >= 1.3), order_band
    assert e_max[-1] < 0.6 * hs[-1]


def test_uniform_grid_agrees_with_scikit_fmm():
    """Against scikit-fmm's first-order distance: within 0.3 h (measured 0.29 h); at the front
    (|d| < 2 h) more accurate than its second-order one (measured 6.9e-3 vs 1.5e-2)."""
    x = np.linspace(0.0, 1.0, 21)
    Z, Y, X = np.meshgrid(x, x, x, indexing="ij")
    exact = np.sqrt((X - 0.5) ** 2 + (Y - 0.45) ** 2 + (Z - 0.55) ** 2) - 0.3
    ours = signed_distance(exact, (x, x, x))
    first = skfmm.distance(exact, dx=0.05, order=1)
    second = skfmm.distance(exact, dx=0.05)
    assert np.abs(ours - first).max() < 0.3 * 0.05
    band = np.abs(exact) < 0.1
    assert np.abs(ours - exact)[band].max() < np.abs(second - exact)[band].max()


def test_no_zero_set_returns_phi_unchanged():
    axes = tuple(np.linspace(0, 1, 4) for _ in range(3))
    phi = np.ones((4, 4, 4))
    out = signed_distance(phi, axes)
    assert np.array_equal(out, phi) and out is not phi


def test_godunov_update_one_two_three_terms():
    inf = np.inf
    a = np.array([[0.0, inf, inf], [0.0, 0.0, inf], [0.0, 0.0, 0.0], [0.0, 5.0, 5.0]])
    h = np.array([[0.5, 1, 1], [1.0, 1.0, 1], [1.0, 1.0, 1.0], [1.0, 2.0, 3.0]])
    d = godunov_update(a, h)
    assert d == pytest.approx([0.5, 1 / np.sqrt(2), 1 / np.sqrt(3), 1.0])


@pytest.mark.parametrize(
    ("phi", "axes", "match"),
    [
        (np.zeros((3, 3)), (np.arange(3.0),) * 3, "nz, ny, nx"),
        (np.zeros((3, 3, 3)), (np.arange(3.0),) * 2, "three node axes"),
        (np.zeros((3, 3, 4)), (np.arange(3.0),) * 3, "x axis must have 4"),
        (np.zeros((3, 3, 3)), (np.array([0, 1, 1.0]),) * 3, "increase strictly"),
        (np.full((3, 3, 3), np.nan), (np.arange(3.0),) * 3, "finite"),
    ],
)
def test_bad_input_rejected(phi, axes, match):
    with pytest.raises(MeshError, match=match):
        signed_distance(phi, axes)


@given(
    values=st.lists(st.floats(-1e6, 1e6), min_size=27, max_size=27),
    cells=st.lists(st.floats(1e-3, 1e3), min_size=6, max_size=6),
)
def test_any_field_keeps_its_signs_and_stays_finite(values, cells):
    """Random fields on random rectilinear grids: finite output, signs kept, zeros stay zero."""
    phi = np.asarray(values).reshape(3, 3, 3)
    c = np.asarray(cells).reshape(3, 2)
    axes = tuple(np.concatenate([[0.0], np.cumsum(row)]) for row in c)
    d = signed_distance(phi, axes)
    assert np.all(np.isfinite(d))
    assert np.array_equal(np.sign(d), np.sign(phi))


@pytest.mark.parametrize("level", [0, 1])
def test_the_band_equals_the_sweeps_within_it(level):
    """``narrow``: Jacobi rounds to the band give the fast sweeps' values wherever |d| <= narrow
    (a crater-like sphere cap and a wavy field on a graded grid), and |d| > narrow beyond."""
    axes, xyz, h = graded_nodes(level)
    sphere = np.linalg.norm(xyz - np.array([0.47, 0.5, 0.95]), axis=-1) - 0.25
    wavy = xyz[..., 2] - 0.6 - 0.1 * np.sin(7 * xyz[..., 0]) * np.cos(5 * xyz[..., 1])
    for phi in (np.tanh(3.0 * sphere), wavy):
        full = signed_distance(phi, axes)
        for narrow in (2 * h, 6 * h):
            band = signed_distance(phi, axes, narrow=narrow)
            inside = np.abs(full) <= narrow
            assert inside.sum() > 100
            assert np.allclose(band[inside], full[inside], rtol=0, atol=1e-12)
            assert np.all(np.abs(band[~inside]) > narrow - 1e-12)
            assert np.array_equal(np.sign(band), np.sign(phi))
