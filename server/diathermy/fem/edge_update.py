"""Updating an edge Laplacian where a few tets changed their coefficient, bit for bit.

A cut or a boiling node changes the conductivity of a few dozen of a million tets; assembling
the potential's matrix anew (weights, degrees, CSR data, unit-diagonal scaling) touched every
edge and node, 50 ms a step on the fixed-electrode grid. The edge weights and node degrees are
sums (``EdgeStiffness.weights``, ``.degree``: ``np.bincount``, which adds its terms in index
order from zero); ``EdgeIncidence`` lists each sum's terms in that order, so the few sums that
changed are recomputed alone and come out exactly as a fresh assembly's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diathermy.fem.edges import EdgeStiffness, LaplacianPattern


def _grouped(keys: np.ndarray, n_groups: int) -> tuple[np.ndarray, np.ndarray]:
    """(ptr, items): the indices of ``keys`` grouped by key, ascending within each group."""
    items = np.argsort(keys, kind="stable")
    ptr = np.zeros(n_groups + 1, dtype=np.int64)
    np.cumsum(np.bincount(keys, minlength=n_groups), out=ptr[1:])
    return ptr, items


def _positions(ptr: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """The item positions of ``groups`` in a grouping (ptr), group after group."""
    start, count = ptr[groups], ptr[groups + 1] - ptr[groups]
    return np.repeat(start - np.cumsum(count) + count, count) + np.arange(int(count.sum()))


def run_sums(count: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The sums of consecutive runs of ``values`` (``count`` terms each), each added in order
    from zero: bit for bit ``np.bincount`` of the same terms."""
    start = np.cumsum(count) - count
    out = np.zeros(count.size)
    for k in range(int(count.max(initial=0))):
        has = np.flatnonzero(count > k)
        out[has] += values[start[has] + k]
    return out


def grouped_sums(
    ptr: np.ndarray, items: np.ndarray, values: np.ndarray, groups: np.ndarray
) -> np.ndarray:
    """For each of ``groups``, the sum of ``values[items[ptr[g]:ptr[g + 1]]]`` added in that
    order from zero."""
    return run_sums(ptr[groups + 1] - ptr[groups], values[items[_positions(ptr, groups)]])


@dataclass(frozen=True)
class EdgeIncidence:
    """Where each tet, edge and node enters the sums of an ``EdgeStiffness``.

    Attributes:
        tet_ptr, tet_pairs: the (tet, edge) couplings of each tet.
        edge_ptr, edge_pairs: the couplings summed into each edge's weight, ascending.
        first_ptr, first_edges / second_ptr, second_edges: the edges whose first / second end
            each node is, ascending (the two sums of its degree).
        kept_of_edge: per edge, its index in the pattern's ``kept_edges`` (-1: an end is not in
            the pattern).
        pair_edge: the edge of each coupling (``EdgeStiffness.pair_edge``).
    """

    tet_ptr: np.ndarray
    tet_pairs: np.ndarray
    edge_ptr: np.ndarray
    edge_pairs: np.ndarray
    first_ptr: np.ndarray
    first_edges: np.ndarray
    second_ptr: np.ndarray
    second_edges: np.ndarray
    kept_of_edge: np.ndarray
    pair_edge: np.ndarray

    def edges_of_tets(self, tets: np.ndarray) -> np.ndarray:
        """The edges (ascending) whose weight the tets ``tets`` enter."""
        return np.unique(self.pair_edge[self.tet_pairs[_positions(self.tet_ptr, tets)]])

    def weights_on(self, stiff: EdgeStiffness, coeff: np.ndarray, edges: np.ndarray) -> np.ndarray:
        """``stiff.weights(coeff)[edges]`` bit for bit, from those edges' couplings only."""
        pairs = self.edge_pairs[_positions(self.edge_ptr, edges)]
        vals = stiff.pair_unit[pairs] * coeff[stiff.pair_tet[pairs]]
        return run_sums(self.edge_ptr[edges + 1] - self.edge_ptr[edges], vals)

    def degree_on(self, w: np.ndarray, nodes: np.ndarray) -> np.ndarray:
        """``stiff.degree(w)[nodes]`` bit for bit."""
        return grouped_sums(self.first_ptr, self.first_edges, w, nodes) + grouped_sums(
            self.second_ptr, self.second_edges, w, nodes
        )

    def incident_edges(self, nodes: np.ndarray) -> np.ndarray:
        """The edges (ascending) with an end in ``nodes``."""
        first = self.first_edges[_positions(self.first_ptr, nodes)]
        second = self.second_edges[_positions(self.second_ptr, nodes)]
        return np.unique(np.concatenate([first, second]))


def edge_incidence(stiff: EdgeStiffness, n_tets: int, pattern: LaplacianPattern) -> EdgeIncidence:
    """The incidence of ``stiff`` (on a mesh of ``n_tets`` tets) and ``pattern``'s kept edges."""
    tet_ptr, tet_pairs = _grouped(stiff.pair_tet, n_tets)
    edge_ptr, edge_pairs = _grouped(stiff.pair_edge, stiff.n_edges)
    first_ptr, first_edges = _grouped(stiff.edges[:, 0], stiff.n_nodes)
    second_ptr, second_edges = _grouped(stiff.edges[:, 1], stiff.n_nodes)
    kept_of_edge = np.full(stiff.n_edges, -1, dtype=np.int64)
    kept_of_edge[pattern.kept_edges] = np.arange(pattern.kept_edges.size)
    return EdgeIncidence(
        tet_ptr,
        tet_pairs,
        edge_ptr,
        edge_pairs,
        first_ptr,
        first_edges,
        second_ptr,
        second_edges,
        kept_of_edge,
        stiff.pair_edge,
    )


@dataclass(frozen=True)
class LaplacianUpdate:
    """A Laplacian matrix's data and its unit-diagonal scaling with a few entries rewritten.

    Attributes:
        data: the matrix's CSR data (a new array).
        scaled_data: D^-1/2 A D^-1/2's data (a new array), bit for bit ``unit_diagonal``'s.
        scale: d = diag^-1/2 on the pattern's nodes (a new array).
        entries: the CSR positions rewritten in ``scaled_data``.
    """

    data: np.ndarray
    scaled_data: np.ndarray
    scale: np.ndarray
    entries: np.ndarray


def update_laplacian(
    pattern: LaplacianPattern,
    inc: EdgeIncidence,
    data: np.ndarray,
    scaled_data: np.ndarray,
    scale: np.ndarray,
    w: np.ndarray,
    edges: np.ndarray,
    nodes: np.ndarray,
    diagonal: np.ndarray,
) -> LaplacianUpdate:
    """The Laplacian ``pattern.matrix`` data with the weights w of ``edges`` and the diagonal
    values ``diagonal`` of ``nodes`` (global indices, their ends and every node whose diagonal
    changed) rewritten, and its scaling updated on those nodes' rows and columns; the inputs
    (the previous data, scaled data and scale) are left as they were."""
    local = pattern.local[nodes]
    inside = local >= 0
    local, diag_values = local[inside], diagonal[inside]
    new = data.copy()
    kept = inc.kept_of_edge[edges]
    on = kept >= 0
    slots = pattern.edge_slots[kept[on]]
    new[slots[:, 0]] = -w[edges[on]]
    new[slots[:, 1]] = -w[edges[on]]
    diag_slots = pattern.diag_slots[local]
    new[diag_slots] = diag_values
    d = scale.copy()
    d[local] = 1.0 / np.sqrt(new[diag_slots])
    around = inc.kept_of_edge[inc.incident_edges(nodes[inside])]
    entries = np.concatenate([diag_slots, pattern.edge_slots[around[around >= 0]].ravel()])
    rows = np.searchsorted(pattern.indptr, entries, side="right") - 1
    scaled = scaled_data.copy()
    scaled[entries] = new[entries] * d[rows] * d[pattern.indices[entries]]
    return LaplacianUpdate(new, scaled, d, entries)
