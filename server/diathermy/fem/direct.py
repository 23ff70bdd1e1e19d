"""Sparse direct factorisation of the small symmetric positive definite blocks the engine
solves exactly (a residual patch, a potential window)."""

from __future__ import annotations

import scipy.sparse as sp
from scipy.sparse.linalg import SuperLU, splu


def spd_factor(A: sp.spmatrix) -> SuperLU:
    """SuperLU of a symmetric positive definite A with a symmetric ordering (minimum degree on
    A + A^T) and diagonal pivots: half the fill and about half the time of SuperLU's defaults
    (COLAMD, partial pivoting), which order for a general matrix. Measured: 0.08 -> 0.04 s on a
    950-node elastic patch at 33x33x65; 26-39 -> 14-22 ms on the fixed electrode's 2601-3240-node
    potential windows. Raises RuntimeError when A is numerically singular."""
    return splu(
        sp.csc_matrix(A),
        permc_spec="MMD_AT_PLUS_A",
        diag_pivot_thresh=0.0,
        options={"SymmetricMode": True},
    )
