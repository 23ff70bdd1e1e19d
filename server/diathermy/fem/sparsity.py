"""A precomputed CSR sparsity pattern so that assembly is one weighted bincount."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True)
class Pattern:
    """CSR structure of the node-node couplings of a tet mesh.

    ``slot[e, a, b]`` is the position in ``indices``/``data`` of entry (tets[e, a], tets[e, b]),
    so the CSR data of sum_e A_e is ``bincount(slot.ravel(), A.ravel())``.
    """

    n: int
    indptr: np.ndarray
    indices: np.ndarray
    slot: np.ndarray  # (n_tets, 4, 4)

    @property
    def nnz(self) -> int:
        return int(self.indices.size)

    def csr(self, local: np.ndarray) -> sp.csr_matrix:
        """Assemble element matrices (n_tets, 4, 4) into an (n, n) CSR matrix."""
        data = np.bincount(self.slot.ravel(), local.ravel(), minlength=self.nnz)
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))


def build_pattern(tets: np.ndarray, n_nodes: int) -> Pattern:
    """The CSR pattern of the node couplings of ``tets`` (n_tets, 4)."""
    rows = np.repeat(tets, 4, axis=1).ravel().astype(np.int64)
    cols = np.tile(tets, (1, 4)).ravel().astype(np.int64)
    key = rows * n_nodes + cols
    uniq, inverse = np.unique(key, return_inverse=True)
    urow, ucol = np.divmod(uniq, n_nodes)
    indptr = np.zeros(n_nodes + 1, dtype=np.int64)
    np.cumsum(np.bincount(urow, minlength=n_nodes), out=indptr[1:])
    return Pattern(
        n=n_nodes,
        indptr=indptr,
        indices=ucol.astype(np.int32 if n_nodes < 2**31 else np.int64),
        slot=inverse.reshape(-1, 4, 4),
    )
