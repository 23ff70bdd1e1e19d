"""The patch correction of a surrogate displacement: solve equilibrium exactly on the few nodes
where the prediction's residual force concentrates (the crater wall), the prediction held fixed
around them; ``equilibrium_guard`` measures the residual it starts from.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from diathermy.fem.direct import spd_factor
from diathermy.physics.equilibrium_guard import relative_residual


@dataclass(frozen=True)
class PatchCorrection:
    """What a patch correction did: u and K u (n_nodes, 3), patch nodes, residuals, time in s."""

    u: np.ndarray
    Ku: np.ndarray
    nodes: int
    residual_before: float
    residual_after: float
    solve_s: float


def node_graph(stiffness: sp.bsr_matrix) -> sp.csr_matrix:
    """Node adjacency (n_nodes, n_nodes), 1 where the 3x3 block K_ij is stored (i ~ j)."""
    n = stiffness.indptr.size - 1
    ones = np.ones(stiffness.indices.size, dtype=np.int8)
    return sp.csr_matrix((ones, stiffness.indices, stiffness.indptr), shape=(n, n))


def residual_patch(
    residual: np.ndarray,
    graph: sp.csr_matrix,
    *,
    threshold: float,
    layers: int,
    max_nodes: int,
) -> np.ndarray:
    """Sorted node indices of the patch: where the residual concentrates, grown by rings.

    Seeds are the nodes whose residual force |r_a| (``residual`` (n_nodes, 3) N) reaches
    ``threshold`` x its maximum; ``layers`` rings of ``graph`` neighbours are added around them.
    A patch above ``max_nodes`` keeps only the strongest half of its seeds, until it fits (at
    worst one seed and its rings). Empty when the residual is zero.
    """
    if not 0.0 < threshold <= 1.0:
        raise ValueError(f"patch threshold must be in (0, 1], got {threshold}")
    if layers < 0 or max_nodes < 1:
        raise ValueError(f"patch layers must be >= 0 and max_nodes >= 1, got {layers}, {max_nodes}")
    scale = float(np.abs(residual).max(initial=0.0))
    if not scale > 0.0:
        return np.zeros(0, dtype=np.int64)
    norm = np.linalg.norm(residual / scale, axis=1)  # scaled: no underflow of tiny forces
    peak = float(norm.max())
    seeds = np.flatnonzero(norm >= threshold * peak)
    seeds = seeds[np.argsort(norm[seeds])[::-1]]  # strongest first
    while True:
        mask = np.zeros(norm.size, dtype=bool)
        mask[seeds] = True
        for _ in range(layers):
            mask |= (graph @ mask.astype(np.int32)) > 0  # int32: no overflow of counts
        if mask.sum() <= max_nodes or seeds.size == 1:
            return np.flatnonzero(mask)
        seeds = seeds[: max(1, seeds.size // 2)]


def block_rows_plan(indptr: np.ndarray, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The stored blocks of the block rows ``nodes`` in a block pattern (its indptr): their
    positions in the data (n_blocks,) and the local row, 0 .. len(nodes) - 1, of each."""
    starts, counts = indptr[nodes], indptr[nodes + 1] - indptr[nodes]
    positions = np.repeat(starts - np.cumsum(counts) + counts, counts) + np.arange(counts.sum())
    return positions, np.repeat(np.arange(nodes.size), counts)


def apply_from_rows(
    blocks: np.ndarray, row: np.ndarray, col: np.ndarray, d: np.ndarray, n_nodes: int
) -> np.ndarray:
    """K d (n_nodes, 3) for a symmetric 3x3-block K and d (m, 3) nonzero on m block rows only,
    from those rows' blocks (n_blocks, 3, 3) with their local row and global column:
    (K d)_c = sum_r K_cr d_r = sum_r K_rc^T d_r, no global mat-vec."""
    Kd = np.einsum("bji,bj->bi", blocks, d[row])
    return np.column_stack([np.bincount(col, Kd[:, i], minlength=n_nodes) for i in range(3)])


def patch_correct(
    stiffness: sp.bsr_matrix,
    f: np.ndarray,
    u: np.ndarray,
    Ku: np.ndarray,
    free: np.ndarray,
    nodes: np.ndarray,
) -> PatchCorrection:
    """Equilibrium solved exactly on the free DOFs of ``nodes``, u held fixed everywhere else.

    Solves K_PP d = (f - K u)_P by a sparse LU (the patch is small: hundreds of nodes) and
    returns u + d with K (u + d) updated from the patch's own block rows (K is symmetric, so
    no global mat-vec). ``stiffness`` is the assembled, unconstrained 3x3-block K; f, u, K u are
    (n_nodes, 3) in N, m, N; free bool (n_nodes, 3); ``nodes`` sorted node indices
    (``residual_patch``). A patch of Dirichlet-fixed or ersatz-only nodes is still solvable:
    outside nodes hold it, and ersatz tets keep K_PP positive definite. Should the factorisation
    still fail or give a non-finite update, u is returned unchanged with ``nodes`` = 0.
    """
    t0 = time.perf_counter()
    before = relative_residual(f, Ku, free)
    n = u.shape[0]
    nodes = np.asarray(nodes, dtype=np.int64)
    m = nodes.size
    dof = free[nodes].ravel()
    if m == 0 or not dof.any():
        return PatchCorrection(u, Ku, 0, before, before, time.perf_counter() - t0)
    local = np.full(n, -1, dtype=np.int64)
    local[nodes] = np.arange(m)
    pos, row = block_rows_plan(stiffness.indptr, nodes)  # row: local block row of each block
    col = stiffness.indices[pos]  # global block column
    blocks = stiffness.data[pos]  # (n_blocks, 3, 3)
    inside = local[col] >= 0
    r_in, c_in = row[inside], local[col[inside]]
    k3 = np.arange(3)
    I = np.broadcast_to((3 * r_in)[:, None, None] + k3[None, :, None], (r_in.size, 3, 3))
    J = np.broadcast_to((3 * c_in)[:, None, None] + k3[None, None, :], (r_in.size, 3, 3))
    A = sp.csr_matrix((blocks[inside].ravel(), (I.ravel(), J.ravel())), shape=(3 * m, 3 * m))
    A = A[dof][:, dof]
    rhs = (f - Ku)[nodes].ravel()[dof]
    flat = np.zeros(3 * m)
    try:  # K_PP is symmetric positive definite
        flat[dof] = spd_factor(A).solve(rhs)
    except RuntimeError:  # numerically singular (an ersatz ratio near 0): leave u as it is
        flat[:] = np.nan
    if not np.all(np.isfinite(flat)):
        return PatchCorrection(u, Ku, 0, before, before, time.perf_counter() - t0)
    d = flat.reshape(m, 3)
    u_new = u.copy()
    u_new[nodes] += d
    # (K d)_c = sum_r K_cr d_r = sum_r K_rc^T d_r over the patch's block rows r
    Ku_new = Ku + apply_from_rows(blocks, row, col, d, n)
    after = relative_residual(f, Ku_new, free)
    return PatchCorrection(u_new, Ku_new, m, before, after, time.perf_counter() - t0)
