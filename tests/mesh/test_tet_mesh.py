"""The Kuhn mesh conforms, has positive volumes, and its topology helpers agree with brute force."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from diathermy.errors import MeshError
from diathermy.fem.geometry import element_geometry
from diathermy.mesh import SIDES, Grid, build_tet_mesh


def test_volumes_positive_and_fill_the_block(small_mesh):
    geom = element_geometry(small_mesh.points, small_mesh.tets)
    assert np.all(geom.volumes > 0)
    assert geom.volumes.sum() == pytest.approx(0.03 * 0.02 * 0.01, rel=1e-12)
    assert small_mesh.n_tets == 6 * small_mesh.grid.n_cells


def test_every_interior_face_shared_by_exactly_two_tets(small_mesh):
    """Conformity: a face is either on the boundary (1 tet) or shared by 2, never 3 or a mismatch."""
    faces = Counter()
    for tet in small_mesh.tets:
        for f in range(4):
            faces[tuple(sorted(np.delete(tet, f)))] += 1
    assert set(faces.values()) <= {1, 2}
    n_boundary = sum(1 for c in faces.values() if c == 1)
    assert n_boundary == small_mesh.surface_triangles().shape[0]
    g = small_mesh.grid
    quads = 2 * ((g.nx - 1) * (g.ny - 1) + (g.nx - 1) * (g.nz - 1) + (g.ny - 1) * (g.nz - 1))
    assert n_boundary == 2 * quads


def test_neighbours_match_brute_force(small_mesh):
    tets = small_mesh.tets
    for t in range(0, small_mesh.n_tets, 7):
        for f in range(4):
            face = set(np.delete(tets[t], f))
            expect = [u for u in range(small_mesh.n_tets) if u != t and face <= set(tets[u])]
            got = small_mesh.neighbours[t, f]
            assert (expect == [got]) if expect else got == -1


def test_boundary_sides_lie_on_their_planes(small_mesh):
    p = small_mesh.points
    lo = np.asarray(small_mesh.grid.origin_m)
    hi = lo + np.asarray(small_mesh.grid.size_m)
    for side in SIDES:
        axis = "xyz".index(side[0])
        value = lo[axis] if side[1] == "-" else hi[axis]
        assert np.allclose(p[small_mesh.boundary_faces[side]][..., axis], value)


def test_node_index_maps_round_trip(small_mesh):
    g = small_mesh.grid
    nodes = np.arange(g.n_nodes)
    assert np.array_equal(g.flat_index(*g.grid_index(nodes)), nodes)
    field = small_mesh.points[:, 2].reshape(g.shape)
    assert np.allclose(field[:, 0, 0], g.axes()[2])


def test_locate_returns_containing_tet(small_mesh, rng):
    g = small_mesh.grid
    lo = np.asarray(g.origin_m)
    xyz = lo + rng.random((200, 3)) * np.asarray(g.size_m)
    tet, lam = small_mesh.locate(xyz)
    assert np.all(lam >= -1e-12) and np.allclose(lam.sum(axis=1), 1.0)
    back = np.einsum("na,nak->nk", lam, small_mesh.points[small_mesh.tets[tet]])
    assert np.allclose(back, xyz)


def test_tets_touching_matches_brute_force(small_mesh, rng):
    """Every tet with one of the nodes as a vertex, and no other, corners and faces included."""
    corners = [0, small_mesh.n_nodes - 1]
    for nodes in (rng.choice(small_mesh.n_nodes, 7, replace=False), corners, []):
        got = small_mesh.tets_touching(np.asarray(nodes, dtype=np.int64))
        want = np.flatnonzero(np.isin(small_mesh.tets, nodes).any(axis=1))
        assert np.array_equal(got, want)
    every = small_mesh.tets_touching(np.arange(small_mesh.n_nodes))
    assert np.array_equal(every, np.arange(small_mesh.n_tets))


@pytest.mark.parametrize("shape", [(1, 3, 3), (3, 3, 0)])
def test_bad_grid_rejected(shape):
    with pytest.raises(MeshError, match="node counts"):
        Grid(shape)


def test_bad_size_rejected():
    with pytest.raises(MeshError, match="positive lengths"):
        Grid((3, 3, 3), size_m=(0.1, -0.1, 0.1))


def test_large_mesh_counts():
    m = build_tet_mesh(Grid((17, 17, 33)))
    assert m.n_tets == 6 * 16 * 16 * 32
    assert m.side_nodes("z-").size == 17 * 33
