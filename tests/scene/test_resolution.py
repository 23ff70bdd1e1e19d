"""The scene's resolution section: defaults around the electrodes, validation naming the field,
and the uniform grid untouched when it is absent."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from diathermy.mesh import Grid, grid_attrs, grid_from_attrs
from diathermy.scene import Resolution, Scene, builtin_scene
from diathermy.scene.resolution import working_region
from diathermy.service.encoding import sample_nodal


def with_resolution(name: str, **res: object) -> Scene:
    data = builtin_scene(name).model_dump()
    data["resolution"] = res
    return Scene.model_validate(data)


def test_without_resolution_the_grid_is_the_uniform_one():
    scene = builtin_scene("default").on_uniform_grid((33, 33, 65))
    assert scene.resolution is None and "resolution" not in scene.model_dump()
    assert scene.node_grid() == Grid(scene.grid, size_m=scene.block_m)
    assert scene.node_shape == (33, 33, 65)
    assert scene.model_copy(update={"resolution": None}) == Scene(name="default", **{
        k: v for k, v in scene.model_dump().items() if k not in ("name", "resolution")
    })  # fmt: skip


@pytest.mark.parametrize(
    ("name", "fine_m", "depth_m"),
    [
        ("default", 1e-3, 3e-3),
        ("fixed-electrode", 0.4e-3, 12e-3),
        ("coagulation", 0.4e-3, 12e-3),
        ("moving-electrode", 1e-3, 3e-3),
        ("moving-electrode-slow", 1e-3, 3e-3),
    ],
)
def test_builtin_scenes_are_graded_under_their_electrodes(name, fine_m, depth_m):
    """Every built-in scene meshes a graded grid: cells of at most fine_m over the electrode's
    contact (or path) + 2 mm, down to depth_m, at most 6.25 mm anywhere; its uniform grid stays
    for the surrogates (``on_uniform_grid``)."""
    scene = builtin_scene(name)
    assert scene.resolution is not None
    g = scene.node_grid()
    assert not g.is_uniform and max(c.max() for c in g.cell_sizes_m()) <= 6.25e-3 + 1e-12
    x, y, z = g.axes()
    el = scene.electrodes[0]
    cx, cy = el.position_m
    under = (np.abs(x[:-1] - cx) < el.radius_m + 2e-3) & (np.abs(x[1:] - cx) < el.radius_m + 2e-3)
    assert np.diff(x)[under].max() <= fine_m + 1e-12
    inside = z[:-1] >= scene.block_m[2] - depth_m - 1e-12
    assert np.diff(z)[inside].max() <= fine_m + 1e-12
    assert np.diff(z)[~inside].min() > fine_m  # below the working region the cells grow
    uniform = scene.on_uniform_grid((9, 9, 17))
    assert uniform.resolution is None and uniform.node_shape == (9, 9, 17)
    assert uniform.model_copy(update={"grid": scene.grid, "resolution": scene.resolution}) == scene


def test_surface_cells_shrink_to_surface_m_at_the_top_only():
    """``surface_m`` refines the z axis toward the top face over the working region; x and y
    and the rest of z are the plain grid's."""
    plain = with_resolution("fixed-electrode")
    refined = with_resolution("fixed-electrode", surface_m=1e-4)
    gp, gr = plain.node_grid(), refined.node_grid()
    assert all(np.array_equal(a, b) for a, b in zip(gr.axes()[:2], gp.axes()[:2], strict=True))
    zp, zr = gp.axes()[2], gr.axes()[2]
    assert np.array_equal(zr[zr <= 0.1 - 12e-3], zp[zp <= 0.1 - 12e-3])
    dz = np.diff(zr)
    assert dz[-1] == pytest.approx(1e-4) and np.all(dz[-1:-8:-1] < 4e-4)
    assert np.all(dz[1:] / dz[:-1] <= 1.25 + 1e-9)
    assert gr.nz == gp.nz + 4  # seven graded cells replace three fine ones
    assert Scene.model_validate_json(refined.model_dump_json()) == refined


def test_default_region_covers_the_contact_or_the_path():
    fixed = with_resolution("fixed-electrode")
    lo, hi = working_region(fixed.resolution, fixed.block_m, fixed.electrodes)
    reach = 1.17e-3 + 2e-3
    assert np.allclose(lo, (0.1 - reach, 0.05 - reach, 0.1 - 12e-3))
    assert np.allclose(hi, (0.1 + reach, 0.05 + reach, 0.1))
    moving = with_resolution("moving-electrode", fine_m=2e-3)
    lo, hi = working_region(moving.resolution, moving.block_m, moving.electrodes)
    wp = np.asarray(moving.electrodes[0].path.waypoints_m)
    assert np.all(wp.min(axis=0) - 3e-3 >= lo[:2]) and np.all(wp.max(axis=0) + 3e-3 <= hi[:2])
    g = moving.node_grid()
    x = g.axes()[0]
    assert np.diff(x)[(x[:-1] >= wp[0, 0]) & (x[1:] <= wp[-1, 0])].max() <= 2e-3 + 1e-12


def test_explicit_region_and_round_trip():
    scene = with_resolution(
        "fixed-electrode", fine_m=1e-3, region_m=((0.09, 0.04, 0.095), (0.11, 0.06, 0.1))
    )
    back = Scene.model_validate_json(scene.model_dump_json())
    assert back == scene and back.node_grid() == scene.node_grid()
    g = scene.node_grid()
    again = grid_from_attrs(grid_attrs(g))
    assert again.shape == g.shape
    assert all(np.array_equal(a, b) for a, b in zip(again.axes(), g.axes(), strict=True))


BAD = {
    "fine_m": st.one_of(st.floats(max_value=1.9e-5), st.floats(min_value=0.051), st.just(math.nan)),
    "growth": st.one_of(st.floats(max_value=0.999), st.floats(min_value=2.001), st.just(math.inf)),
    "max_cell_m": st.one_of(st.floats(max_value=0.0), st.floats(min_value=0.0501)),
    "margin_m": st.one_of(st.floats(max_value=-1e-9), st.floats(min_value=0.1001)),
    "depth_m": st.one_of(st.floats(max_value=0.0), st.floats(min_value=1.001)),
    "surface_m": st.one_of(st.floats(max_value=1.9e-5), st.floats(min_value=0.0501)),
    "fine_z_m": st.one_of(
        st.floats(max_value=1.9e-5), st.floats(min_value=0.051), st.just(math.inf)
    ),
    "deep_m": st.one_of(st.floats(max_value=0.0), st.floats(min_value=1.001), st.just(math.nan)),
    "deep_z_m": st.one_of(st.floats(max_value=1.9e-5), st.floats(min_value=0.0501)),
}


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(sorted(BAD)).flatmap(lambda k: st.tuples(st.just(k), BAD[k])))
def test_bad_values_name_the_field(bad):
    field, value = bad
    with pytest.raises(ValidationError, match=f"resolution.{field}"):
        with_resolution("fixed-electrode", **{field: value})


def test_a_cell_height_of_its_own_refines_z_alone():
    """``fine_z_m`` sets the working region's cell height; its width stays fine_m, and the
    grid is the one ``Grid.graded`` makes with the per-axis spacings."""
    flat = with_resolution("fixed-electrode", fine_m=1e-3)
    tall = with_resolution("fixed-electrode", fine_m=1e-3, fine_z_m=0.25e-3)
    assert tall.resolution is not None and tall.resolution.fine_spacing_m == (1e-3, 1e-3, 0.25e-3)
    g0, g1 = flat.node_grid(), tall.node_grid()
    assert g1.axes()[0].tolist() == g0.axes()[0].tolist()  # x and y as before
    assert g1.axes()[1].tolist() == g0.axes()[1].tolist()
    z = g1.axes()[2]
    inside = z[:-1] >= tall.block_m[2] - tall.resolution.depth_m - 1e-12
    assert np.diff(z)[inside].max() <= 0.25e-3 + 1e-12
    assert g1.nz > g0.nz
    assert Resolution(fine_m=1e-3).fine_spacing_m == (1e-3, 1e-3, 1e-3)
    # a surface refinement shrinks from the cell height, which it must not exceed
    Resolution(fine_m=1e-3, fine_z_m=0.5e-3, surface_m=0.2e-3)
    with pytest.raises(ValidationError, match=r"surface_m .* must not exceed fine_z_m"):
        Resolution(fine_m=1e-3, fine_z_m=0.5e-3, surface_m=0.6e-3)
    with pytest.raises(ValidationError, match="max_cell_m .* must be at least fine_z_m"):
        Resolution(fine_m=1e-3, fine_z_m=3e-3, max_cell_m=2e-3)


def test_a_deep_tier_keeps_the_cells_bounded_below_the_working_region():
    """``deep_m`` keeps the cells under the working region at most ``deep_z_m`` tall down to that
    depth, grading up to it by at most the growth ratio; the region itself, x and y are as
    without it, and the step reports' region (``Scene.working_region``) reaches down to it."""
    plain = with_resolution("fixed-electrode")
    deep = with_resolution("fixed-electrode", deep_m=40e-3)
    assert deep.resolution is not None and deep.resolution.deep_cell_m == pytest.approx(0.8e-3)
    gp, gd = plain.node_grid(), deep.node_grid()
    assert all(np.array_equal(a, b) for a, b in zip(gd.axes()[:2], gp.axes()[:2], strict=True))
    top = deep.block_m[2]
    zp, zd = gp.axes()[2], gd.axes()[2]
    region_d, region_p = zd[zd >= top - 12e-3 - 1e-12], zp[zp >= top - 12e-3 - 1e-12]
    assert region_d.shape == region_p.shape and np.allclose(region_d, region_p, rtol=0, atol=1e-12)
    dz = np.diff(zd)
    tier = zd[:-1] >= top - 40e-3 - 1e-12
    assert dz[tier].max() <= 0.8e-3 * (1 + 1e-9)
    assert dz[~tier].min() >= dz[tier].max() * (1 - 1e-9)  # and grow on below it
    assert np.all(np.maximum(dz[1:] / dz[:-1], dz[:-1] / dz[1:]) <= 1.25 + 1e-9)
    assert gd.nz > gp.nz + 28 - 10  # 28 mm more at <= 0.8 mm, against the cells it replaces
    (lo, hi), (lo0, hi0) = deep.working_region(), plain.working_region()
    assert lo[2] == pytest.approx(top - 40e-3) and lo[:2] == lo0[:2] and hi == hi0
    assert Scene.model_validate_json(deep.model_dump_json()) == deep
    # a tier of its own height; one below the block's bottom ends there
    tall = with_resolution("fixed-electrode", deep_m=40e-3, deep_z_m=2e-3)
    dz = np.diff(tall.node_grid().axes()[2])
    assert dz[tall.node_grid().axes()[2][:-1] >= top - 40e-3 - 1e-12].max() <= 2e-3 * (1 + 1e-9)
    whole = with_resolution("fixed-electrode", fine_m=1e-3, deep_m=0.5)
    assert np.diff(whole.node_grid().axes()[2]).max() <= 2e-3 * (1 + 1e-9)
    assert whole.working_region()[0][2] == 0.0


def test_the_fixed_electrode_ships_its_tier_and_coagulation_does_not():
    """The 50 W crater drills ~80 mm in 12 s (benchmarks/results/fixed_depth.md): the scene's
    cells under the contact stay at most 0.8 mm tall to 90 mm; coagulation has no crater."""
    fixed, coag = builtin_scene("fixed-electrode"), builtin_scene("coagulation")
    z = fixed.node_grid().axes()[2]
    tier = z[:-1] >= fixed.block_m[2] - 90e-3 - 1e-12
    assert np.diff(z)[tier].max() <= 0.8e-3 * (1 + 1e-9)
    assert fixed.working_region()[0][2] == pytest.approx(fixed.block_m[2] - 90e-3)
    assert coag.resolution is not None and coag.resolution.deep_m is None
    assert coag.working_region()[0][2] == pytest.approx(coag.block_m[2] - 12e-3)


def test_a_deep_tier_above_the_region_or_of_the_wrong_height_is_refused():
    assert Resolution(fine_m=4e-3, deep_m=0.1).deep_cell_m == 6.25e-3  # twice, within the cap
    with pytest.raises(ValidationError, match=r"deep_m .* must exceed depth_m"):
        Resolution(deep_m=10e-3)
    with pytest.raises(ValidationError, match=r"deep_z_m .* must lie between fine_m"):
        Resolution(deep_m=40e-3, deep_z_m=0.2e-3)
    with pytest.raises(ValidationError, match=r"deep_z_m .* must lie between fine_z_m"):
        Resolution(fine_z_m=0.8e-3, deep_m=40e-3, deep_z_m=0.5e-3)
    with pytest.raises(ValidationError, match=r"deep_z_m .* and max_cell_m"):
        Resolution(deep_m=40e-3, max_cell_m=2e-3, deep_z_m=3e-3)
    with pytest.raises(ValidationError, match=r"resolution: deep_m .* must reach below"):
        with_resolution(
            "fixed-electrode",
            deep_m=5e-3,
            region_m=((0.09, 0.04, 0.08), (0.11, 0.06, 0.1)),
        )


def test_inconsistent_or_huge_requests_are_refused():
    with pytest.raises(ValidationError, match="max_cell_m .* must be at least fine_m"):
        Resolution(fine_m=2e-3, max_cell_m=1e-3)
    with pytest.raises(ValidationError, match="surface_m .* must not exceed fine_m"):
        Resolution(fine_m=4e-4, surface_m=5e-4)
    with pytest.raises(ValidationError, match="region_m: high corner"):
        Resolution(region_m=((0.1, 0.05, 0.1), (0.09, 0.06, 0.1)))
    with pytest.raises(ValidationError, match="resolution: the graded grid would have"):
        with_resolution("moving-electrode", fine_m=1e-4, growth=1.01)


def test_sample_nodal_on_graded_axes_is_exact_for_linear_fields():
    scene = with_resolution("fixed-electrode", fine_m=2e-3)
    g = scene.node_grid()
    p = g.points()
    field = (1.0 + 2.0 * p[:, 0] - 3.0 * p[:, 1] + 5.0 * p[:, 2]).reshape(g.shape)
    rng = np.random.default_rng(0)
    pts = rng.uniform((0, 0, 0), g.size_m, size=(50, 3))
    got = sample_nodal(field, pts, origin_m=g.origin_m, spacing_m=None, axes_m=g.axes())
    assert np.allclose(got, 1.0 + 2.0 * pts[:, 0] - 3.0 * pts[:, 1] + 5.0 * pts[:, 2])


def test_the_fixed_electrode_resolves_the_boiling_layer_at_its_surface():
    """The first cut converges once the top cells over the contact are fine/4 (0.1 mm; 0.4 / 0.1 mm
    within 2 % of 0.2 / 0.05 mm, benchmarks/results/convergence.md): the scene ships them, over
    its working region only, growing back to 0.4 mm below."""
    fixed = builtin_scene("fixed-electrode")
    assert fixed.resolution is not None and fixed.resolution.surface_m == pytest.approx(0.1e-3)
    grid = fixed.node_grid()
    x, y, z = grid.axes()
    dz = np.diff(z)
    assert dz[-1] == pytest.approx(0.1e-3)
    below_over_above = dz[-8:-1] / dz[-7:]  # down from the surface: growing by <= 1.25
    assert np.all((below_over_above >= 1 - 1e-9) & (below_over_above <= 1.25 + 1e-9))
    assert 0.3e-3 < dz[-8] <= 0.4e-3 * (1 + 1e-9)  # the region's own cells below
    for axis in (x, y):  # the sideways cells stay the region's
        assert 0.3e-3 < np.diff(axis).min() <= 0.4e-3 * (1 + 1e-9)
    assert builtin_scene("coagulation").resolution.surface_m is None  # type: ignore[union-attr]
