"""The phi = 0 triangle mesh: areas of known cuts, orientation, empty when nothing is cut, export."""

from __future__ import annotations

import meshio
import numpy as np
import pytest

from diathermy.mesh import Grid
from diathermy.physics.cut_surface import cut_surface, write_cut_surface
from diathermy.physics.levelset import advance, initial_level_set

GRID = Grid((21, 17, 31), size_m=(0.03, 0.016, 0.02), origin_m=(0.1, -0.2, 0.005))


def normals(surface):
    v = surface.vertices[surface.faces]
    return np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), v.mean(axis=1)


def test_nothing_cut_gives_an_empty_mesh():
    s = cut_surface(initial_level_set(GRID), GRID)  # phi = 0 on the top is the original surface
    assert s.n_vertices == 0 and s.faces.shape == (0, 3) and s.area_m2() == 0


def test_plane_cut_area_position_and_orientation():
    z_cut = 0.0163  # removed above it, between node layers
    phi = initial_level_set(GRID) - (0.025 - z_cut)
    s = cut_surface(phi, GRID)
    assert s.area_m2() == pytest.approx(0.03 * 0.016, rel=1e-6)
    assert np.allclose(s.vertices[:, 2], z_cut, atol=1e-9)
    lo, hi = np.array(GRID.origin_m), np.array(GRID.origin_m) + GRID.size_m
    assert np.all(s.vertices >= lo - 1e-9) and np.all(s.vertices <= hi + 1e-9)
    n, _ = normals(s)
    assert np.all(n[:, 2] > 0)  # out of the healthy tissue, into the removed region


def test_sphere_cut_area_and_orientation():
    c, R = np.array([0.115, -0.192, 0.014]), 0.005
    phi = np.linalg.norm(GRID.points() - c, axis=1).reshape(GRID.shape) - R
    s = cut_surface(phi, GRID)
    assert s.area_m2() == pytest.approx(4 * np.pi * R**2, rel=0.03)
    assert np.abs(np.linalg.norm(s.vertices - c, axis=1) - R).max() < 0.1 * min(GRID.spacing_m)
    n, mid = normals(s)
    assert np.all(np.einsum("ij,ij->i", n, mid - c) < 0)  # into the removed ball


def test_crater_surface_stops_at_the_original_top():
    speed = np.zeros(GRID.shape)
    speed[:, 6:11, 10:21] = 1e-3  # a trench 4 mm x 10 mm footprint (node to node)
    phi = advance(initial_level_set(GRID), speed, GRID.spacing_m, 3.0).phi
    s = cut_surface(phi, GRID)
    top = GRID.origin_m[2] + GRID.size_m[2]
    floor = np.abs(s.vertices[s.faces].mean(axis=1)[:, 2] - (top - 3e-3)) < 1e-9
    assert s.area_m2() > 0 and s.vertices[:, 2].max() <= top + 1e-9  # float32 vertices
    n, _ = normals(s)
    assert floor.any() and np.all(n[floor, 2] > 0)
    on_top = np.all(np.abs(s.vertices[s.faces][..., 2] - top) < 1e-9, axis=1)
    assert not on_top.any()  # no triangle lies in the untouched top plane


@pytest.mark.parametrize("suffix", [".vtu", ".ply"])
def test_write_round_trip(tmp_path, suffix):
    phi = initial_level_set(GRID) - 0.004
    s = cut_surface(phi, GRID)
    path = tmp_path / f"cut{suffix}"
    write_cut_surface(path, s)
    back = meshio.read(path)
    assert np.allclose(back.points, s.vertices) and np.array_equal(
        back.cells_dict["triangle"], s.faces
    )
