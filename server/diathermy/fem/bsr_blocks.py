"""Operations on the 3x3 blocks of a block-sparse (BSR) elasticity matrix: which block row a
stored block is in, zeroing the rows and columns of constrained DOFs, and the symmetric Jacobi
scaling D^-1/2 K D^-1/2 of chosen blocks (the mechanics solver updates a few of them per cut).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def constrain_blocks(
    data: np.ndarray, rows: np.ndarray, cols: np.ndarray, constrained: np.ndarray
) -> np.ndarray:
    """3x3 blocks (m, 3, 3) of K at block rows/cols (m,) with the rows and columns of the
    constrained DOFs (bool (n_nodes, 3)) zeroed and their diagonal kept; a new array."""
    out = data * ~(constrained[rows][:, :, None] | constrained[cols][:, None, :])
    on_diag = np.flatnonzero(rows == cols)
    idx = np.arange(3)
    diag_blocks = out[on_diag]
    kept = constrained[rows[on_diag]]
    diag_blocks[:, idx, idx] = np.where(kept, data[on_diag][:, idx, idx], diag_blocks[:, idx, idx])
    out[on_diag] = diag_blocks
    return out


def scale_blocks(
    data: np.ndarray, s3: np.ndarray, rows: np.ndarray, cols: np.ndarray
) -> np.ndarray:
    """Blocks (m, 3, 3) at block rows/cols (m,) scaled s_row x block x s_col by the per-node
    scales s3 (n_nodes, 3): the symmetric Jacobi scaling D^-1/2 K D^-1/2 of those blocks."""
    out = data * s3[rows][:, :, None]
    out *= s3[cols][:, None, :]  # in place: 2x faster than one expression, same bits
    return out


def block_rows(K: sp.bsr_matrix) -> np.ndarray:
    """Block row of each stored 3x3 block of ``K``."""
    return np.repeat(np.arange(K.indptr.size - 1), np.diff(K.indptr))


def constrain_in_place(K: sp.bsr_matrix, constrained: np.ndarray) -> np.ndarray:
    """Zero the rows and columns of constrained DOFs in place, keep their diagonal; returns it."""
    diag = K.diagonal()
    K.data[:] = constrain_blocks(K.data, block_rows(K), K.indices, constrained.reshape(-1, 3))
    return diag
