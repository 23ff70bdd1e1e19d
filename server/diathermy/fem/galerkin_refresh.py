"""The coarse operators of a kept AMG hierarchy brought up to date for a changed fine operator.

A kept smoothed-aggregation hierarchy (``fem.solvers.KrylovSolver`` with ``stale_factor``) takes
a new fine operator A when a few tets are cut, while its prolongators P_k and coarse operators
A_k stay those of the build-time operator A_b. With the prolongators kept, the Galerkin coarse
operators of A differ from the kept ones by the restricted change alone,

    A_{k+1} - A_{k+1,b} = P_k^T (A_k - A_{k,b}) P_k =: D_{k+1},    D_0 = A - A_b,

and D_0 lives on the blocks the cuts changed, so each D_{k+1} is formed from the rows of P_k
under the support of D_k: a product over a few hundred rows (20-50 ms on the fixed electrode's
169 k nodes), not the 1.1 s of R A P on every level. Each refresh starts from the build-time
operators, so the coarse levels are a function of (A_b, A) alone and a checkpoint that rebuilds
the hierarchy of A_b and then sets A repeats them bit for bit. No operator is copied: the coarse
levels are written here only, and the caller announces its in-place writes to the fine one
(``before_write``), so the build-time values of what changed are saved as they go (22 MB on
the fixed electrode, where copies of A_b and P_0 took 518 MB). The coarsest level's direct
solver (a pseudo-inverse of a few hundred rows) is formed again for its new operator.

For a Jacobi-scaled operator A = S K S (``scale``) the change is taken in the build's units,
P^T S_b (K - K_b) S_b P, with the fine prolongator diag(S_b / S) P: see ``refresh`` for why.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from diathermy.fem.bsr_blocks import block_rows, scale_blocks
from diathermy.fem.multigrid import coarse_solver


@dataclass(frozen=True)
class RefreshStats:
    """What one refresh did: fine-level blocks changed since the build, coarse entries written
    per level, and whether it applied (False: the fine operator's sparsity differs)."""

    applied: bool
    changed_blocks: int = 0
    coarse_entries: tuple[int, ...] = ()


def _blocksize(A: Any) -> tuple[int, int]:
    """(rows, columns) of A's blocks: BSR's blocksize, (1, 1) for CSR."""
    if sp.issparse(A) and A.format == "bsr":
        return int(A.blocksize[0]), int(A.blocksize[1])
    return 1, 1


def _block_rows(indptr: np.ndarray, blocks: np.ndarray) -> np.ndarray:
    """The block row of each stored block (indices into the data) of a BSR/CSR pattern."""
    return np.searchsorted(indptr, blocks, side="right") - 1


def _block_keys(A: Any) -> np.ndarray:
    """Stored block (row, column) of a canonical BSR/CSR matrix as one sorted int64 key each."""
    return block_rows(A).astype(np.int64) * np.int64(A.indices.max(initial=0) + 1) + A.indices


def _blocks_in_rows(indptr: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The stored blocks (indices into the data) of block rows ``rows``, row by row, and how
    many each row holds."""
    starts, counts = indptr[rows], np.diff(indptr)[rows]
    offsets = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    return np.repeat(starts, counts) + offsets, counts


def _entries(blocks: np.ndarray, size: int) -> np.ndarray:
    """Positions in the flat data of the stored blocks ``blocks`` of ``size`` entries each."""
    return (blocks[:, None] * size + np.arange(size)).ravel()


def _csr_of_blocks(
    rows: np.ndarray, cols: np.ndarray, data: np.ndarray, shape: tuple[int, int]
) -> sp.csr_matrix:
    """CSR of the blocks data (m, br, bc) at block rows/columns (m,)."""
    m, br, bc = data.shape
    i = (rows * br)[:, None, None] + np.arange(br)[None, :, None]
    j = (cols * bc)[:, None, None] + np.arange(bc)[None, None, :]
    ij = (np.broadcast_to(i, data.shape).ravel(), np.broadcast_to(j, data.shape).ravel())
    return sp.csr_matrix((data.ravel(), ij), shape=shape)


class _Saved:
    """Build-time values of an array that is written in place after the build: each entry
    (index along the first axis) is saved before its first write (``save``), so ``values`` gives
    any entry's build-time value without a copy of the whole array."""

    def __init__(self, array: np.ndarray) -> None:
        self.array = array
        self._at = np.zeros(0, dtype=np.int64)
        self._val = np.zeros((0, *array.shape[1:]), dtype=array.dtype)

    def save(self, idx: np.ndarray) -> None:
        """Save the entries at idx not saved yet (call before writing them)."""
        new = np.setdiff1d(np.asarray(idx, dtype=np.int64), self._at)
        if new.size:
            at = np.concatenate([self._at, new])
            order = np.argsort(at, kind="stable")
            self._at = at[order]
            self._val = np.concatenate([self._val, self.array[new]])[order]

    def values(self, idx: np.ndarray) -> np.ndarray:
        """The build-time entries at idx."""
        out = self.array[idx].copy()
        if self._at.size:
            hit = np.minimum(np.searchsorted(self._at, idx), self._at.size - 1)
            saved = self._at[hit] == idx
            out[saved] = self._val[hit[saved]]
        return out


class _Edits:
    """Entries of a flat array that this module sets relative to their build-time values; the
    entries set by the last ``set`` and not by this one go back to them."""

    def __init__(self, flat: np.ndarray) -> None:
        self.flat = flat
        self.pos = np.zeros(0, dtype=np.int64)
        self._saved = _Saved(flat)

    def base(self, pos: np.ndarray) -> np.ndarray:
        """The build-time values at the positions ``pos``."""
        return self._saved.values(pos)

    def set(self, pos: np.ndarray, values: np.ndarray) -> None:
        """flat[pos] = values (unique positions), every other entry its build-time value."""
        self._saved.save(pos)
        old = np.setdiff1d(self.pos, pos, assume_unique=True)
        self.flat[old] = self.base(old)
        self.flat[pos] = values
        self.pos = pos


class GalerkinRefresh:
    """The build-time operators of a pyamg hierarchy ``ml``, and ``refresh(A)``, which makes its
    coarse levels the Galerkin operators of A with the kept prolongators (see module docstring).

    Args:
        ml: a pyamg ``MultilevelSolver`` whose levels hold BSR or CSR operators in canonical
            form (sorted, no duplicates) and R_k = P_k^T, as ``smoothed_aggregation_solver``
            gives for a symmetric operator.
        coarse_solver: the coarse solver's name as given to pyamg ("pinv", ...), formed anew for
            the refreshed coarsest operator.
        scale: the fine operator is D^-1/2 K D^-1/2 with this D^-1/2 (n,) at the build; see
            ``refresh``.
    """

    def __init__(
        self,
        ml: Any,
        coarse_solver: str = "pinv",
        scale: np.ndarray | None = None,
        fine: Any = None,
    ) -> None:
        levels = ml.levels
        A0 = levels[0].A if fine is None else fine
        self._ml = ml
        self._coarse_solver = coarse_solver
        self._indptr, self._indices = A0.indptr, A0.indices  # patterns are never written
        self._fine = _Saved(A0.data)  # the caller announces in-place writes (``before_write``)
        self._fine_bs = _blocksize(A0)
        self._scale = None if scale is None else np.array(scale, dtype=float)
        for lvl in levels[1:]:
            if not lvl.A.has_canonical_format:
                lvl.A.sum_duplicates()
        self._keys = [_block_keys(lvl.A) for lvl in levels[1:]]
        self._key_width = [np.int64(lvl.A.indices.max(initial=0) + 1) for lvl in levels[1:]]
        self._coarse = [_Edits(lvl.A.data.reshape(-1)) for lvl in levels[1:]]
        self._dirty: np.ndarray | None = np.zeros(0, dtype=np.int64)  # fine blocks (see mark)
        self._p_edits: _Edits | None = None
        if self._scale is not None and len(levels) > 1:
            P0, R0 = levels[0].P, levels[0].R
            self._p_edits = _Edits(P0.data.reshape(-1))
            self._r_edits = _Edits(R0.data.reshape(-1))
            self._r_keys = _block_keys(R0)
            self._r_width = np.int64(R0.indices.max(initial=0) + 1)

    def before_write(self, data: np.ndarray, blocks: np.ndarray) -> None:
        """The caller is about to write ``data[blocks]`` in place: if ``data`` is the build-time
        operator's, its values there are saved first."""
        if np.may_share_memory(data, self._fine.array):
            self._fine.save(blocks)

    def mark(self, blocks: np.ndarray | None) -> None:
        """Note the fine operator's stored blocks (indices into its data) that may have changed
        since the last refresh (None: any of them)."""
        if blocks is None or self._dirty is None:
            self._dirty = None
        else:
            self._dirty = np.union1d(self._dirty, np.asarray(blocks, dtype=np.int64))

    def refresh(self, A: Any, scale: np.ndarray | None = None) -> RefreshStats:
        """Set the coarse levels to the Galerkin operators of A (the fine operator, same sparsity
        as at the build). ``applied`` is False when A's sparsity differs, or a coarse change
        falls outside the kept coarse sparsity: the coarse levels are then the build-time ones.

        ``scale``: A = S K S with S = diag(scale) where the build's was S_b K_b S_b. A cut
        changes the scale of the nodes it softens (by 1e3 for ersatz tissue), so the build-time
        prolongator P, made from the near-nullspace S_b^-1 B, is then in the wrong units there.
        The fine level's prolongator becomes diag(S_b / S) P, the one a build would make from
        S^-1 B with the same aggregates, and the coarse operators the Galerkin products of the
        stiffness change in the build's units, P^T S_b (K - K_b) S_b P, which softened tets
        cannot make stiffer. Refreshed in the scaled units instead, level 1's spectral radius
        grew 1.3-1.8x, the Chebyshev smoothing tuned to the build-time radius amplified those
        modes, and a 9x9x17 block with large cuts took 44-89 CG iterations against 38-76 with
        the kept coarse levels; in the build's units 30-37 (a fresh hierarchy 27-30).
        """
        if (
            A.shape != self._ml.levels[0].A.shape
            or _blocksize(A) != self._fine_bs
            or not (A.indptr is self._indptr or np.array_equal(A.indptr, self._indptr))
            or not (A.indices is self._indices or np.array_equal(A.indices, self._indices))
        ):
            self._reset()
            return RefreshStats(applied=False)
        ratio = None
        if scale is not None and self._scale is not None and len(self._ml.levels) > 1:
            ratio = self._scale / np.asarray(scale, dtype=float)
        nb = self._indices.size
        where = np.arange(nb) if self._dirty is None else self._dirty
        br, bc = self._fine_bs
        now = A.data[where].reshape(where.size, br, bc)
        if ratio is not None:  # S_b K S_b = (S_b / S) A (S_b / S)
            r = ratio.reshape(-1, br)
            now = scale_blocks(now, r, _block_rows(self._indptr, where), self._indices[where])
        built = self._fine.values(where)
        diff = now.reshape(where.size, -1) - built.reshape(where.size, -1)
        keep = np.any(diff != 0.0, axis=1)
        changed = where[keep]
        self._dirty = changed  # the blocks that differ from the build's stay candidates
        delta = _csr_of_blocks(
            _block_rows(self._indptr, changed),
            self._indices[changed],
            diff[keep].reshape(-1, br, bc),
            self._ml.levels[0].A.shape,
        )
        slots = []
        for k in range(len(self._coarse)):
            delta = self._restrict(k, delta)
            slot = self._slots(k, delta)
            if slot is None:
                self._reset()
                return RefreshStats(applied=False, changed_blocks=int(changed.size))
            slots.append(slot)
        for k, (pos, values) in enumerate(slots):
            self._write(k, pos, values)
        if self._p_edits is not None:
            self._rescale_prolongator(ratio)
        return RefreshStats(True, int(changed.size), tuple(p.size for p, _ in slots))

    def _rescale_prolongator(self, ratio: np.ndarray | None) -> None:
        """The fine level's P := diag(ratio) P_b and R := P^T on the rows whose ratio is not 1
        (the others their build-time values; None: all of them)."""
        P = self._ml.levels[0].P
        assert self._p_edits is not None
        br, bc = _blocksize(P)
        if ratio is None:
            rows = np.zeros(0, dtype=np.int64)
        else:
            rows = np.flatnonzero(np.any(ratio.reshape(-1, br) != 1.0, axis=1))
        blocks, counts = _blocks_in_rows(P.indptr, rows)
        if ratio is None or blocks.size == 0:
            self._p_edits.set(np.zeros(0, dtype=np.int64), np.zeros(0))
            self._r_edits.set(np.zeros(0, dtype=np.int64), np.zeros(0))
            return
        block_rows = np.repeat(rows, counts)
        pos = _entries(blocks, br * bc)
        factor = ratio.reshape(-1, br)[block_rows]  # (blocks, br)
        values = self._p_edits.base(pos).reshape(-1, br, bc) * factor[:, :, None]
        self._p_edits.set(pos, values.ravel())
        r_block = np.searchsorted(
            self._r_keys, P.indices[blocks].astype(np.int64) * self._r_width + block_rows
        )
        self._r_edits.set(_entries(r_block, br * bc), values.transpose(0, 2, 1).ravel())

    def _restrict(self, k: int, delta: sp.csr_matrix) -> sp.csr_matrix:
        """P_k^T delta P_k (R_k = P_k^T) with the build-time P_k, formed on the rows of P_k
        under delta's support only (canonical CSR, no stored zeros)."""
        n = self._ml.levels[k + 1].A.shape[0]
        if delta.nnz == 0:
            return sp.csr_matrix((n, n))
        support = np.union1d(np.flatnonzero(np.diff(delta.indptr)), delta.indices)
        Ps = self._prolongator_rows(k, support)
        out = sp.csr_matrix(Ps.T @ (delta[support][:, support] @ Ps))
        out.sum_duplicates()
        out.eliminate_zeros()
        return out

    def _prolongator_rows(self, k: int, rows: np.ndarray) -> sp.csr_matrix:
        """The build-time P_k's rows ``rows`` (sorted, unique) as CSR."""
        P = self._ml.levels[k].P
        br, bc = _blocksize(P)
        brows = np.unique(rows // br)
        blocks, counts = _blocks_in_rows(P.indptr, brows)
        if k == 0 and self._p_edits is not None:
            data = self._p_edits.base(_entries(blocks, br * bc)).reshape(-1, br, bc)
        else:
            data = P.data[blocks].reshape(-1, br, bc)
        local = np.repeat(np.arange(brows.size), counts)
        block = _csr_of_blocks(local, P.indices[blocks], data, (brows.size * br, P.shape[1]))
        return block[np.searchsorted(brows, rows // br) * br + rows % br]

    def _slots(self, k: int, delta: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray] | None:
        """Positions in level k+1's flat data of delta's entries, and their values (None: one
        lies outside the kept sparsity)."""
        A = self._ml.levels[k + 1].A
        coo = delta.tocoo()
        br, bc = _blocksize(A)
        keys = self._keys[k]
        key = (coo.row // br).astype(np.int64) * self._key_width[k] + coo.col // bc
        if key.size == 0:
            return np.zeros(0, dtype=np.int64), np.zeros(0)
        slot = np.minimum(np.searchsorted(keys, key), keys.size - 1)
        if not np.array_equal(keys[slot], key):
            return None
        return (slot * br + coo.row % br) * bc + coo.col % bc, coo.data

    def _write(self, k: int, pos: np.ndarray, values: np.ndarray) -> None:
        """Level k+1's operator := its build-time one + values at pos."""
        edits = self._coarse[k]
        before = edits.pos.size
        edits.set(pos, edits.base(pos) + values)
        if k == len(self._coarse) - 1 and (before or pos.size):
            self._ml.coarse_solver = coarse_solver(self._coarse_solver)

    def _reset(self) -> None:
        """Every coarse level and the fine prolongator back to their build-time values."""
        for k in range(len(self._coarse)):
            self._write(k, np.zeros(0, dtype=np.int64), np.zeros(0))
        if self._p_edits is not None:
            self._rescale_prolongator(None)
