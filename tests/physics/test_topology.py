"""Per-tet status, cut volume, crater depth, loose fragments and the electrode contact height."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from diathermy.fem.geometry import element_geometry
from diathermy.mesh import Grid, build_tet_mesh
from diathermy.physics.levelset import advance, initial_level_set, volume_incidence
from diathermy.physics.topology import (
    _kuhn_negative_count,
    bottom_tets,
    changed_tets,
    contact_height,
    crater_depth,
    cut_volume,
    evaluate_topology,
    healthy_components,
    loose_fragments,
    removed_fraction,
    removed_tets,
    tissue_nodes,
)


def reference_fraction(values: np.ndarray) -> float:
    """Curry–Schoenberg: the CDF at 0 of a linear function over a simplex (distinct values)."""
    return sum(
        max(-v, 0.0) ** 3 / np.prod([w - v for j, w in enumerate(values) if j != i])
        for i, v in enumerate(values)
    )


def lattice_fraction(values: np.ndarray, n: int = 40) -> float:
    """Share of a fine barycentric lattice (cell centres of the sub-tets' corners) with phi < 0."""
    i, j, k = np.meshgrid(*(np.arange(n) + 0.25,) * 3, indexing="ij")
    inside = i + j + k < n
    lam = np.stack([i, j, k], -1)[inside] / n
    lam = np.column_stack([1 - lam.sum(1), lam])
    return float((lam @ values < 0).mean())


@pytest.fixture(scope="module")
def mesh():
    return build_tet_mesh(Grid((9, 7, 11), size_m=(0.02, 0.012, 0.016), origin_m=(0.0, 0.0, 0.0)))


@pytest.fixture(scope="module")
def volumes(mesh):
    return element_geometry(mesh.points, mesh.tets).volumes


@settings(max_examples=100, deadline=None)
@given(
    st.lists(st.floats(-1, 1).filter(lambda v: abs(v) > 1e-3), min_size=4, max_size=4, unique=True)
)
def test_fraction_equals_the_closed_form(values):
    values = np.array(values)
    got = removed_fraction(values, np.array([[0, 1, 2, 3]]))[0]
    if np.min(np.abs(values[:, None] - values[None, :]) + np.eye(4)) > 1e-2:
        assert got == pytest.approx(reference_fraction(list(values)), abs=1e-9)
    assert 0 <= got <= 1
    perm = np.random.default_rng(0).permutation(4)
    assert removed_fraction(values[perm], np.array([[0, 1, 2, 3]]))[0] == pytest.approx(
        got, abs=1e-14
    )


def test_fraction_matches_sampling_and_handles_ties():
    tet = np.array([[0, 1, 2, 3]])
    for values in (
        [-1, 1, 1, 1],
        [-1, -1, 1, 1],
        [-1, -1, -1, 1],
        [-3, 0.5, 2, 0.1],
        [-0.2, -2, 3, 1],
    ):
        v = np.array(values, dtype=float)
        assert removed_fraction(v, tet)[0] == pytest.approx(lattice_fraction(v), abs=0.02)
    assert removed_fraction(np.array([-1.0, 1, 1, 1]), tet)[0] == pytest.approx(1 / 8)
    assert removed_fraction(np.array([-1.0, -1, 1, 1]), tet)[0] == pytest.approx(1 / 2)
    assert removed_fraction(np.array([-3.0, 1, 1, 1]), tet)[0] == pytest.approx(27 / 64)
    assert removed_fraction(np.array([0.0, 0, 0, 0]), tet)[0] == 0  # the untouched surface
    assert removed_fraction(np.array([-1.0, 0, 0, 0]), tet)[0] == 1
    assert removed_fraction(np.array([-1.0, -1, -1, -1]), tet)[0] == 1


def test_structured_count_equals_the_gather(mesh, rng):
    phi = rng.normal(size=mesh.n_nodes)
    assert np.array_equal(_kuhn_negative_count(phi, mesh), (phi < 0)[mesh.tets].sum(axis=1))


def test_half_space_cut_volume_is_exact(mesh, volumes):
    g = mesh.grid
    z0 = 0.0113  # between node layers
    phi = z0 - mesh.points[:, 2]  # removed above z0
    frac = removed_fraction(phi, mesh.tets)
    assert cut_volume(frac, volumes) == pytest.approx(0.02 * 0.012 * (0.016 - z0), rel=1e-12)
    assert crater_depth(phi, mesh) == pytest.approx(0.016 - z0, rel=1e-12)
    # the mask rounds the fraction: its volume is within the cut layer of tets
    mask_volume = volumes[removed_tets(frac)].sum()
    assert abs(mask_volume - 0.02 * 0.012 * (0.016 - z0)) <= 0.02 * 0.012 * g.spacing_m[2]


def box_level_set(g: Grid, lo: tuple[int, int, int], hi: tuple[int, int, int]) -> np.ndarray:
    """A removed box of whole cells between node layers lo..hi (k, j, i), shape (nz, ny, nx).

    -1 inside, -1e-9 on the faces, +1 outside: every tet of the box has all nodes < 0, tets
    outside keep removed fractions of order 1e-9 (exact 0 on the faces would leave the tets whose
    nodes all lie on two faces of the box at phi = 0, not removed).
    """
    k, j, i = np.meshgrid(*(np.arange(n) for n in g.shape), indexing="ij")
    idx = (k, j, i)
    inside = np.all([(idx[a] > lo[a]) & (idx[a] < hi[a]) for a in range(3)], axis=0)
    closed = np.all([(idx[a] >= lo[a]) & (idx[a] <= hi[a]) for a in range(3)], axis=0)
    return np.where(inside, -1.0, np.where(closed, -1e-9, 1.0))


def test_removed_box_is_exact(mesh, volumes):
    g = mesh.grid
    dx, dy, dz = g.spacing_m
    # a box from node layer k = 3 up through the top
    phi = box_level_set(g, (3, 1, 2), (g.nz + 1, 5, 8))
    topo = evaluate_topology(phi, mesh, volumes)
    box = (8 - 2) * dx * (5 - 1) * dy * (g.nz - 1 - 3) * dz
    assert topo.cut_volume_m3 == pytest.approx(box, rel=1e-8)
    assert volumes[topo.removed].sum() == pytest.approx(box, rel=1e-12)
    assert topo.crater_depth_m == pytest.approx((g.nz - 1 - 3) * dz, rel=1e-8)
    assert not topo.loose.any()


def test_nothing_cut_at_the_start(mesh, volumes):
    topo = evaluate_topology(initial_level_set(mesh.grid), mesh, volumes)
    assert topo.cut_volume_m3 == 0 and topo.crater_depth_m == 0
    assert not topo.removed.any() and not topo.loose.any()


def test_a_removed_slab_detaches_the_block_above(mesh):
    zc = mesh.centroids()[:, 2]
    slab = (zc > 0.006) & (zc < 0.009)
    comps = healthy_components(slab, mesh)
    assert comps.n_components == 2 and comps.anchored.sum() == 1
    assert np.array_equal(comps.loose(), zc > 0.009)
    assert np.all(comps.labels[slab] == -1)
    # a pillar of healthy tissue through the slab keeps the block attached
    xc = mesh.centroids()[:, 0]
    with_pillar = slab & ~((xc > 0.008) & (xc < 0.012))
    assert not loose_fragments(with_pillar, mesh).any()


def test_an_undercut_ring_frees_a_plug():
    """A ring cut from the top plus a disc under it frees the plug; the ring alone does not."""
    mesh = build_tet_mesh(Grid((9, 21, 21), size_m=(0.02, 0.02, 0.004)))
    volumes = element_geometry(mesh.points, mesh.tets).volumes
    p = mesh.points * 1e3  # mm
    r = np.hypot(p[:, 0] - 10, p[:, 1] - 10)
    ring = np.abs(r - 6) - 1.5  # removed where 4.5 mm < r < 7.5 mm, all the way down
    standing = evaluate_topology(ring * 1e-3, mesh, volumes)
    assert standing.removed.any() and not standing.loose.any()  # the plug stands on the bottom
    disc = np.maximum(r - 7.5, np.abs(p[:, 2] - 1.5) - 0.5)  # removed 1 mm < z < 2 mm
    cup = np.minimum(np.maximum(ring, 1.0 - p[:, 2]), disc) * 1e-3
    topo = evaluate_topology(cup, mesh, volumes)
    c = mesh.centroids() * 1e3
    rc = np.hypot(c[:, 0] - 10, c[:, 1] - 10)
    plug = ~topo.removed & (rc < 6) & (c[:, 2] > 1.5)
    assert plug.sum() > 1000 and np.array_equal(topo.loose, plug)
    assert evaluate_topology(cup, mesh, volumes, previous=topo).loose is topo.loose  # reused
    assert np.array_equal(evaluate_topology(cup, mesh, volumes, previous=standing).loose, plug)


def reference_components(removed: np.ndarray, mesh) -> np.ndarray:
    """Component of every healthy tet by a graph over all healthy tets (-1 for removed)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    t = np.repeat(np.arange(mesh.n_tets), 4)
    nb = mesh.neighbours.ravel()
    keep = (nb >= 0) & ~removed[t] & ~removed[np.maximum(nb, 0)]
    graph = sp.coo_matrix((np.ones(keep.sum()), (t[keep], nb[keep])), shape=(mesh.n_tets,) * 2)
    _, comp = connected_components(graph.tocsr(), directed=False)
    return np.where(removed, -1, comp)


def same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal up to renaming the labels."""
    pairs = np.unique(np.column_stack([a, b]), axis=0)
    return len(np.unique(pairs[:, 0])) == len(pairs) == len(np.unique(pairs[:, 1]))


@pytest.mark.parametrize("density", [0.05, 0.3, 0.6])
def test_components_equal_the_all_tets_graph(mesh, density):
    rng = np.random.default_rng(int(density * 100))
    removed = rng.random(mesh.n_tets) < density
    comps = healthy_components(removed, mesh)
    ref = reference_components(removed, mesh)
    assert same_partition(comps.labels, ref)
    anchored = np.zeros(ref.max() + 1, dtype=bool)
    anchored[ref[bottom_tets(mesh) & ~removed]] = True
    assert np.array_equal(comps.loose(), ~removed & ~anchored[np.maximum(ref, 0)])
    assert comps.n_components == len(np.unique(ref[ref >= 0]))


def test_bottom_tets_have_a_face_on_z_minus(mesh):
    bottom = bottom_tets(mesh)
    faces = {tuple(sorted(f)) for f in mesh.boundary_faces["z-"]}
    expect = [any(tuple(sorted(np.delete(t, f))) in faces for f in range(4)) for t in mesh.tets]
    assert np.array_equal(bottom, expect)


def test_changed_tets():
    old = np.array([False, True, False, False])
    assert changed_tets(old, old).size == 0
    assert np.array_equal(changed_tets(old, np.array([True, True, False, True])), [0, 3])


def bowl(g: Grid, depth: float, radius: float, cx: float, cy: float) -> np.ndarray:
    """phi = z_s(x, y) - z, z_s a paraboloid crater of the given depth below the top."""
    x, y, z = g.axes()
    r2 = (x[None, :] - cx) ** 2 + (y[:, None] - cy) ** 2
    z_s = z[-1] - depth * np.maximum(0.0, 1 - r2 / radius**2)
    return z_s[None] - z[:, None, None]


def test_contact_height_follows_a_crater_down():
    g = Grid((33, 33, 33), size_m=(0.02, 0.02, 0.01))
    top = g.origin_m[2] + g.size_m[2]
    cx, cy, R = 0.0101, 0.0098, 0.006
    heights = []
    for depth in (0.0, 0.001, 0.003, 0.006):
        phi = bowl(g, depth, R, cx, cy)
        tol = 0.25 * max(g.spacing_m) ** 2 * 2 * depth / R**2 + 1e-12  # bilinear in (x, y)
        z = contact_height(phi, g, cx, cy)
        assert z == pytest.approx(top - depth, abs=tol)
        heights.append(float(z))
        off = contact_height(phi, g, np.array([cx + 0.5 * R, 0.019]), np.array([cy, cy]))
        assert off[0] == pytest.approx(top - 0.75 * depth, abs=tol)
        assert off[1] == top  # outside the crater: the original surface (phi = 0 there)
    assert heights == sorted(heights, reverse=True) and heights[0] == top
    # a column cut all the way through: the electrode would sit on the bottom
    assert contact_height(np.full(g.shape, -1.0), g, cx, cy) == g.origin_m[2]
    with pytest.raises(ValueError):
        contact_height(phi, g, 0.5, cy)


def test_contact_height_on_an_advanced_level_set():
    g = Grid((21, 9, 9), size_m=(0.008, 0.008, 0.01))
    speed = np.zeros(g.shape)
    speed[:, 3:6, 3:6] = 1e-3
    phi = advance(initial_level_set(g), speed, g.spacing_m, 2.0).phi
    top = g.origin_m[2] + g.size_m[2]
    assert contact_height(phi, g, 0.004, 0.004) == pytest.approx(top - 2e-3, abs=1e-9)
    assert contact_height(phi, g, 0.0005, 0.004) == top


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 1.0))
def test_tissue_nodes_are_the_nodes_of_tets_not_removed(seed, share_removed):
    """Any removed mask: the nodes of the tets left, by the gather and by the incidence product
    alike; every node of a removed-only neighbourhood is out."""
    mesh = build_tet_mesh(Grid((4, 5, 6), size_m=(0.01, 0.01, 0.01)))
    volumes = element_geometry(mesh.points, mesh.tets).volumes
    removed = np.random.default_rng(seed).random(mesh.n_tets) < share_removed
    gathered = tissue_nodes(removed, mesh.tets, mesh.n_nodes)
    product = tissue_nodes(
        removed, mesh.tets, mesh.n_nodes, volume_incidence(mesh.tets, volumes, mesh.n_nodes)
    )
    assert np.array_equal(gathered, product)
    for node in range(mesh.n_nodes):
        around = np.flatnonzero((mesh.tets == node).any(axis=1))
        assert gathered[node] == bool((~removed[around]).any())
