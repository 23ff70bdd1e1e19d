"""Loose fragments: the face-connected pieces of healthy tissue and which of them float.

A component of the healthy-tet face graph is anchored when the constrained DOFs on its nodes fix
all 6 rigid-body modes; one that is not floats on the ersatz material alone (``mechanics``
removes it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from diathermy.fem.elastic import rigid_body_modes
from diathermy.fem.window_box import nodes_in_box
from diathermy.mesh import TetMesh


@dataclass(frozen=True)
class Fragments:
    """Face-connected components of the healthy tets and which of them float."""

    labels: np.ndarray  # (n_tets,) component of each healthy tet, -1 elsewhere
    n_components: int
    loose: np.ndarray = field(repr=False)  # (n_tets,) healthy tets of unanchored components


def find_fragments(
    mesh: TetMesh, healthy: np.ndarray, constrained: np.ndarray, *, tol: float = 1e-9
) -> Fragments:
    """Components of the healthy-tet face graph; a component is anchored when the constrained
    DOFs (bool (3 n_nodes,)) on its nodes fix all 6 rigid-body modes (rank-6 Gram matrix)."""
    healthy = np.asarray(healthy, dtype=bool)
    ids = np.flatnonzero(healthy)
    local = np.full(mesh.n_tets, -1, dtype=np.int64)
    local[ids] = np.arange(ids.size)
    nb = mesh.neighbours[ids]
    keep = nb >= 0
    keep[keep] = healthy[nb[keep]]
    rows = np.repeat(np.arange(ids.size), 4).reshape(-1, 4)[keep]
    graph = sp.csr_matrix((np.ones(rows.size), (rows, local[nb[keep]])), (ids.size, ids.size))
    n_comp, comp = connected_components(graph, directed=False)
    labels = np.full(mesh.n_tets, -1, dtype=np.int64)
    labels[ids] = comp
    # (component, constrained node) pairs, then the Gram matrix of the rigid modes at the
    # constrained DOFs (nodes without one add nothing: leaving them out keeps the sort small).
    tets = mesh.tets[ids]
    node_held = np.any(np.asarray(constrained).reshape(-1, 3), axis=1, keepdims=False)
    held = node_held[tets]
    pairs = np.unique((comp[:, None] * np.int64(mesh.n_nodes) + tets)[held])
    pc, pn = np.divmod(pairs, mesh.n_nodes)
    B = rigid_body_modes(mesh.points).reshape(mesh.n_nodes, 3, 6)
    cm = constrained.reshape(-1, 3)[pn]  # (n_pairs, 3)
    gram = np.zeros(n_comp * 36)
    for i in range(3):
        sel = cm[:, i]
        Bi = B[pn[sel], i]
        slots = pc[sel][:, None] * 36 + np.arange(36)
        gram += np.bincount(
            slots.ravel(), (Bi[:, :, None] * Bi[:, None, :]).ravel(), minlength=gram.size
        )
    gram = gram.reshape(n_comp, 6, 6)
    smallest = np.linalg.eigvalsh(gram)[:, 0]
    scale = np.trace(gram, axis1=1, axis2=2).max(initial=0.0)
    anchored = smallest > tol * max(scale, 1.0)
    loose = np.zeros(mesh.n_tets, dtype=bool)
    loose[ids] = ~anchored[comp]
    return Fragments(labels, n_comp, loose)


def update_fragments(
    mesh: TetMesh,
    previous: Fragments,
    previous_healthy: np.ndarray,
    healthy: np.ndarray,
    constrained: np.ndarray,
    centroids: np.ndarray,
    *,
    margin: float = 3.0,
) -> Fragments | None:
    """The fragments after a cut removed tets from ``previous_healthy`` (bool (n_tets,)), when a
    search near the cut proves the components unchanged; None when it cannot (a full search is
    needed: tets healed, a fragment was loose, the cut touches a constrained node, or the
    healthy neighbours of the removed tets are not connected within ``margin`` x the cut's
    extent of it). ``centroids`` (n_tets, 3) m of ``mesh``.

    Why it is exact: a path between two healthy tets that ran through removed tets enters and
    leaves them at their healthy neighbours, which stay connected; the constrained nodes of a
    component all stay (no removed tet touches one), so its anchoring does too.
    """
    healthy = np.asarray(healthy, dtype=bool)
    if previous.loose.any() or np.any(healthy & ~previous_healthy):
        return None
    removed = np.flatnonzero(previous_healthy & ~healthy)
    if removed.size == 0:
        return previous
    held = np.any(np.asarray(constrained).reshape(-1, 3), axis=1)
    if held[mesh.tets[removed]].any():
        return None
    nb = mesh.neighbours[removed].ravel()
    border = np.unique(nb[nb >= 0])
    border = border[healthy[border]]
    lost = np.unique(previous.labels[removed])
    if border.size == 0 or not np.isin(lost, previous.labels[border]).all():
        return None  # a component may have been cut away whole
    corners = mesh.points[mesh.tets[removed]]
    extent = float(np.max(corners.max(axis=1) - corners.min(axis=1)))
    lo = corners.min(axis=(0, 1)) - margin * extent
    hi = corners.max(axis=(0, 1)) + margin * extent
    inside = nodes_in_box(centroids, lo, hi)  # the tets whose centroid is in the box
    region = inside[healthy[inside]]
    local = np.full(mesh.n_tets, -1, dtype=np.int64)
    local[region] = np.arange(region.size)
    nbr = mesh.neighbours[region]
    keep = nbr >= 0
    keep[keep] = local[nbr[keep]] >= 0
    rows = np.repeat(np.arange(region.size), 4).reshape(-1, 4)[keep]
    graph = sp.csr_matrix(
        (np.ones(rows.size), (rows, local[nbr[keep]])), (region.size, region.size)
    )
    _, comp = connected_components(graph, directed=False)
    if np.unique(comp[local[border]]).size != 1:
        return None
    labels = previous.labels.copy()
    labels[removed] = -1
    return Fragments(labels, previous.n_components, previous.loose)
