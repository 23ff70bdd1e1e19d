"""The loose-fragment search near a cut (physics.fragments.update_fragments): where it answers,
it agrees with the full search; where the cut may have detached or unanchored tissue, it
declines and the full search decides."""

from __future__ import annotations

import numpy as np
import pytest

from diathermy.mesh import Grid, build_tet_mesh
from diathermy.physics.constraints import clamped_bottom
from diathermy.physics.fragments import find_fragments, update_fragments


@pytest.fixture(scope="module")
def mesh():
    return build_tet_mesh(Grid((7, 9, 11)))


def _same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    """Labels (n,) with -1 outside define the same components up to numbering."""
    if not np.array_equal(a < 0, b < 0):
        return False
    pairs = np.unique(np.stack([a[a >= 0], b[b >= 0]]), axis=1)
    return np.unique(pairs[0]).size == pairs.shape[1] == np.unique(pairs[1]).size


def test_growing_craters_agree_with_the_full_search(mesh):
    constrained = clamped_bottom(mesh).mask(3 * mesh.n_nodes)
    c = mesh.centroids()
    top = c[:, 2].max()
    healthy = np.ones(mesh.n_tets, dtype=bool)
    previous = find_fragments(mesh, healthy, constrained)
    answered = 0
    for r in np.linspace(0.01, 0.05, 9):  # a crater under the middle of the top face
        new = healthy & (np.linalg.norm(c - [0.1, 0.05, top], axis=1) > r)
        got = update_fragments(mesh, previous, healthy, new, constrained, c)
        full = find_fragments(mesh, new, constrained)
        if got is not None:
            answered += 1
            assert np.array_equal(got.loose, full.loose)
            assert _same_partition(got.labels, full.labels)
            assert got.n_components == full.n_components
        previous, healthy = full, new
    assert answered >= 5  # a growing crater is the common case


def test_a_cut_that_detaches_a_piece_goes_to_the_full_search(mesh):
    """A shell cut around a block of tissue, its last face cut in this step: the piece inside
    floats; the search near the cut cannot connect the inside to the outside and declines."""
    constrained = clamped_bottom(mesh).mask(3 * mesh.n_nodes)
    c = mesh.centroids()
    d = np.abs(c - [0.1, 0.05, 0.0])
    inner = (d[:, 0] < 0.02) & (d[:, 1] < 0.02) & (c[:, 2] > 0.05) & (c[:, 2] < 0.08)
    shell = (d[:, 0] < 0.045) & (d[:, 1] < 0.035) & (c[:, 2] > 0.03) & ~inner
    gap = shell & (c[:, 1] < 0.03)  # the -y face of the shell, cut last
    before = ~(shell & ~gap)
    after = ~shell
    previous = find_fragments(mesh, before, constrained)
    assert not previous.loose.any()
    full = find_fragments(mesh, after, constrained)
    assert np.array_equal(full.loose, inner)  # the piece inside floats
    assert update_fragments(mesh, previous, before, after, constrained, c) is None


def test_declines_healing_loose_and_constrained_cuts(mesh):
    constrained = clamped_bottom(mesh).mask(3 * mesh.n_nodes)
    c = mesh.centroids()
    healthy = np.ones(mesh.n_tets, dtype=bool)
    base = find_fragments(mesh, healthy, constrained)
    dent = healthy & (np.linalg.norm(c - [0.1, 0.05, c[:, 2].max()], axis=1) > 0.02)
    assert update_fragments(mesh, base, dent, healthy, constrained, c) is None  # healed
    bottom = healthy & (c[:, 2] > c[:, 2].min() + 1e-9) | (c[:, 0] > 0.05)
    assert update_fragments(mesh, base, healthy, bottom, constrained, c) is None  # clamped nodes
    assert update_fragments(mesh, base, healthy, healthy, constrained, c) is base  # nothing cut
