"""Graded grids: geometric grading around a working box, explicit spacing semantics, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from diathermy.errors import MeshError
from diathermy.fem.geometry import element_geometry
from diathermy.mesh import Grid, build_tet_mesh
from diathermy.mesh.grading import MAX_AXIS_NODES, graded_axis, refined_end


def small_graded() -> Grid:
    return Grid.graded(
        (0.012, 0.004, 0.006), (0.016, 0.006, 0.01), 1e-3, growth=1.5, size_m=(0.03, 0.01, 0.01)
    )


def test_graded_grid_is_fine_in_the_box_and_grows_outside():
    g = small_graded()
    x, y, z = g.axes()
    dx, dy, dz = g.cell_sizes_m()
    inside = (x[:-1] >= 0.012 - 1e-12) & (x[1:] <= 0.016 + 1e-12)
    assert inside.sum() == 4 and np.allclose(dx[inside], 1e-3)
    for d in (dx, dy, dz):
        ratio = d[1:] / d[:-1]
        assert np.all(ratio <= 1.5 + 1e-9) and np.all(ratio >= 1 / 1.5 - 1e-9)
    assert z[-1] == 0.01 and dz[-1] == pytest.approx(1e-3)  # box reaches the top: fine there
    assert x[0] == 0.0 and x[-1] == 0.03 and not g.is_uniform
    assert g.min_spacing_m == pytest.approx((1e-3, 1e-3, 1e-3))


def test_graded_tet_mesh_fills_the_block_and_locates_points(rng):
    g = small_graded()
    mesh = build_tet_mesh(g)
    geom = element_geometry(mesh.points, mesh.tets)
    assert np.all(geom.volumes > 0)
    assert geom.volumes.sum() == pytest.approx(0.03 * 0.01 * 0.01, rel=1e-12)
    xyz = rng.random((300, 3)) * np.asarray(g.size_m)
    tet, lam = mesh.locate(xyz)
    assert np.all(lam >= -1e-12)
    back = np.einsum("na,nak->nk", lam, mesh.points[mesh.tets[tet]])
    assert np.allclose(back, xyz)


def test_spacing_is_explicit_uniform_only():
    u = Grid((5, 6, 7), size_m=(0.03, 0.02, 0.01))
    assert u.is_uniform and u.min_spacing_m == u.spacing_m
    assert np.array_equal(u.cell_sizes_m()[0], np.full(6, 0.005))
    with pytest.raises(MeshError, match="no single node spacing"):
        _ = small_graded().spacing_m


def test_graded_axes_equal_to_linspace_reproduce_the_uniform_mesh():
    u = Grid((5, 6, 7), size_m=(0.03, 0.02, 0.01), origin_m=(0.1, -0.2, 0.0))
    g = Grid.from_axes(*u.axes())
    assert np.array_equal(build_tet_mesh(g).points, build_tet_mesh(u).points)
    xyz = np.array([[0.111, -0.191, 0.0041], [0.129, -0.181, 0.0099]])
    assert all(np.array_equal(a, b) for a, b in zip(g.cell_of(xyz), u.cell_of(xyz), strict=True))


def test_region_point_and_whole_block():
    x = graded_axis(0.0, 0.1, (0.05, 0.05), 0.002, 1.3)
    i = np.searchsorted(x, 0.05) - 1
    assert x[i + 1] - x[i] == pytest.approx(0.002) and np.diff(x).min() == pytest.approx(0.002)
    assert x[i] + x[i + 1] == pytest.approx(0.1)
    whole = graded_axis(0.0, 0.1, (0.0, 0.1), 0.01, 1.3)
    assert np.allclose(whole, np.linspace(0.0, 0.1, 11))


def test_the_top_of_the_region_shrinks_to_its_end_cell():
    """Cells of at most fine over the region, shrinking by the growth ratio to the end cell at
    its high side (the top surface); below the region they grow as before."""
    x = graded_axis(0.0, 0.1, (0.088, 0.1), 4e-4, 1.25, max_cell=6.25e-3, hi_cell=1e-4)
    d = np.diff(x)
    assert x[-1] == 0.1 and d[-1] == pytest.approx(1e-4)
    inside = x[:-1] >= 0.088 - 1e-12
    ratio = d[inside][1:] / d[inside][:-1]
    assert np.all(ratio <= 1 + 1e-9) and np.all(ratio >= 1 / 1.25 - 1e-9)
    assert d[inside].max() <= 4e-4 + 1e-12
    top = np.flatnonzero(d < d[inside].max() * (1 - 1e-6))
    assert top.size == 7 and np.all(top >= d.size - 8)  # 1e-4 * 1.25^k for k < 7, at the top
    same = graded_axis(0.0, 0.1, (0.088, 0.1), 4e-4, 1.25, max_cell=6.25e-3)
    below = x <= 0.088 + 1e-12
    assert np.array_equal(x[below], same[same <= 0.088 + 1e-12])  # unchanged below the region
    plain = graded_axis(0.0, 0.1, (0.05, 0.1), 0.01, 1.3)
    assert np.array_equal(graded_axis(0.0, 0.1, (0.05, 0.1), 0.01, 1.3, hi_cell=0.01), plain)


@pytest.mark.parametrize("length", [5e-5, 1.5e-4, 5e-4, 1.2e-3, 7.3e-3])
def test_refined_end_fills_any_length(length):
    """Any region length: cells that add up to it, at most fine, shrinking toward the end by at
    most the growth ratio, the end cell no longer than the fine one."""
    d = refined_end(length, 4e-4, 1e-4, 1.25)
    assert d.sum() == pytest.approx(length, rel=1e-12) and np.all(d > 0)
    assert d.max() <= 4e-4 * (1 + 1e-9) and d[-1] <= max(1e-4, length) * (1 + 1e-9)
    if d.size > 1:
        ratio = d[:-1] / d[1:]
        assert np.all(ratio <= 1.25 * (1 + 1e-9)) and np.all(ratio >= 1 - 1e-9)


def test_refined_end_with_a_growth_a_rounding_error_above_one():
    """A growth of 1 + 2e-16 (hypothesis found it) asks for 3e15 graded cells by the ratio alone;
    the length bounds them: end-sized cells, as with no grading, at once."""
    d = refined_end(1.0, 1.0, 0.5, 1.0000000000000002)
    assert d.sum() == pytest.approx(1.0, rel=1e-12) and d.size == 2
    assert np.allclose(d, 0.5)


def test_max_cell_caps_the_far_field():
    x = graded_axis(0.0, 0.2, (0.0, 0.01), 1e-3, 1.5, max_cell=5e-3)
    assert np.diff(x).max() <= 5e-3 * (1 + 1e-9)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"fine_m": 0.0}, "fine spacing"),
        ({"fine_m": math.nan}, "fine_m"),
        ({"growth": 0.9}, "growth ratio"),
        ({"growth": 3.0}, "growth ratio"),
        ({"fine_m": 1e-7}, "nodes on one axis"),
        ({"region_lo_m": (0.5, 0.0, 0.0), "region_hi_m": (0.6, 0.1, 0.1)}, "outside"),
        ({"region_lo_m": (0.1, 0.0, 0.0), "region_hi_m": (0.05, 0.1, 0.1)}, "lo <= hi"),
        ({"max_cell_m": 1e-4}, "largest cell"),
        ({"top_cell_m": 2e-3}, "end cell .* must not exceed"),
        ({"top_cell_m": -1e-4}, "end cell"),
        ({"bottom_tier_m": (0.02, 5e-4)}, "tier cell .* must lie between"),
        ({"bottom_tier_m": (0.02, 1.0), "max_cell_m": 5e-3}, "tier cell .* must lie between"),
        ({"bottom_tier_m": (-0.02, 2e-3)}, "tier length"),
        ({"bottom_tier_m": (0.02, math.nan)}, "tier cell"),
        ({"region_lo_m": (0.0, 0.0)}, "region_lo_m"),
        ({"size_m": (0.2, -0.1, 0.1)}, "block size"),
        ({"origin_m": (0.0, math.inf, 0.0)}, "origin"),
    ],
)
def test_bad_grading_rejected(kwargs, match):
    args = {"region_lo_m": (0.09, 0.04, 0.09), "region_hi_m": (0.11, 0.06, 0.1), "fine_m": 1e-3}
    args.update(kwargs)
    lo, hi, fine = args.pop("region_lo_m"), args.pop("region_hi_m"), args.pop("fine_m")
    with pytest.raises(MeshError, match=match):
        Grid.graded(lo, hi, fine, **args)


@pytest.mark.parametrize(
    ("axes", "match"),
    [
        (([0.0, 0.1], [0.0, 0.1], [0.0, 0.1, 0.1]), "strictly increasing"),
        (([0.0, 0.1], [0.0, 0.1], [0.0]), ">= 2"),
        (([0.0, math.nan], [0.0, 0.1], [0.0, 0.1]), "finite"),
    ],
)
def test_bad_axes_rejected(axes, match):
    with pytest.raises(MeshError, match=match):
        Grid.from_axes(*axes)


def test_axes_must_match_shape_and_box():
    with pytest.raises(MeshError, match="must be 3 numbers"):
        Grid((2, 2, 3), size_m=(1, 1, 1), node_axes_m=((0, 0.5, 0.7, 1), (0, 1), (0, 1)))
    with pytest.raises(MeshError, match="run from the origin"):
        Grid((2, 2, 3), size_m=(1, 1, 1), node_axes_m=((0, 0.5, 0.9), (0, 1), (0, 1)))


@given(
    lo=st.floats(-1.0, 1.0),
    length=st.floats(1e-3, 1.0),
    a=st.floats(-0.5, 1.5),
    width=st.floats(0.0, 1.0),
    fine=st.floats(1e-4, 2.0),
    growth=st.floats(1.0, 2.0),
    end=st.one_of(st.none(), st.floats(1e-3, 1.0)),
)
def test_graded_axis_properties_or_clear_error(lo, length, a, width, fine, growth, end):
    """Any input, with or without a refined high end, gives a valid increasing axis from lo to
    hi, or a MeshError; never garbage."""
    hi = lo + length
    region = (lo + a * length, lo + (a + width) * length)
    hi_cell = None if end is None else end * fine * length
    try:
        x = graded_axis(lo, hi, region, fine * length, growth, hi_cell=hi_cell)
    except MeshError:
        return
    d = np.diff(x)
    assert x[0] == lo and x[-1] == hi and np.all(d > 0) and x.size <= MAX_AXIS_NODES
    assert d.min() <= fine * length * (1 + 1e-9)
    # adjacent cells differ by at most the growth ratio (a factor 2 more where a short gap
    # gets equal cells shorter than the fine ones)
    r = d[1:] / d[:-1]
    assert np.all(r <= 2 * growth * (1 + 1e-6)) and np.all(r >= 1 / (2 * growth * (1 + 1e-6)))


@given(
    gap=st.floats(0.0, 0.5),
    first=st.floats(1e-4, 1e-2),
    length=st.floats(1e-4, 0.5),
    ratio=st.floats(1.0, 10.0),
    growth=st.floats(1.0, 2.0),
)
def test_a_lower_tier_bounds_its_cells_and_keeps_the_growth(gap, first, length, ratio, growth):
    """Below the region the cells fill the gap exactly, stay at most the tier's cell over the
    tier's length, and grow by at most the growth ratio (twice it where a gap too short for
    growth gets equal cells)."""
    lo, a = 0.0, gap
    try:
        x = graded_axis(
            lo, a + 0.01, (a, a + 0.01), first, growth, 0.05, lo_tier=(length, first * ratio)
        )
    except MeshError:
        return
    d = np.diff(x)
    assert x[0] == lo and np.all(d > 0)
    below = x[1:] <= a + 1e-12
    in_tier = below & (x[1:] >= a - length + first * ratio)
    if in_tier.any():
        assert d[in_tier].max() <= first * ratio * (1 + 1e-9)
    r = d[1:] / d[:-1]
    assert np.all(r <= 2 * growth * (1 + 1e-6)) and np.all(r >= 1 / (2 * growth * (1 + 1e-6)))


@given(
    values=st.lists(
        st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-5, 5)),
        min_size=0,
        max_size=4,
    )
)
def test_graded_grid_bad_inputs_raise_mesh_error(values):
    """Random region/fine vectors either build a grid or raise MeshError, nothing else."""
    try:
        g = Grid.graded(values, (0.2, 0.1, 0.1), values[0] if values else 1e-3)
    except MeshError:
        return
    assert g.n_nodes >= 8 and all(np.all(np.diff(a) > 0) for a in g.axes())


def test_subnormal_fine_spacing_is_a_mesh_error():
    """(hi - lo) / fine overflows to inf: a clear MeshError, not an OverflowError."""
    with pytest.raises(MeshError, match="nodes"):
        Grid.graded((0.0, 0.0, 0.0), (0.2, 0.1, 0.1), 5e-324)
