"""Vectorised P1 linear elasticity: element stiffness, BSR assembly, eigenstress load, strain.

Degrees of freedom are node-major: DOF ``3 * node + i`` is component i (x, y, z) of a node, so
the stiffness matrix is a (3 n_nodes)^2 BSR matrix of 3x3 blocks on the node pattern of
``fem.sparsity``. Young's modulus is per tet (cut tissue takes an ersatz modulus), Poisson's ratio
one number for the mesh.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from diathermy.fem.geometry import ElementGeometry
from diathermy.fem.sparsity import Pattern


def lame_parameters(youngs_modulus: np.ndarray | float, nu: float) -> tuple:
    """Lame's lambda = E nu / ((1 + nu)(1 - 2 nu)) and mu = E / (2 (1 + nu)), in Pa."""
    if not -1.0 < nu < 0.5:
        raise ValueError(f"Poisson's ratio must lie in (-1, 0.5), got {nu}")
    E = np.asarray(youngs_modulus, dtype=float)
    return E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), E / (2.0 * (1.0 + nu))


def elastic_local(
    geom: ElementGeometry, youngs_modulus: np.ndarray | float, nu: float
) -> np.ndarray:
    """Element stiffness (n_tets, 4, 4, 3, 3): entry [e, a, b, i, j] couples DOF (a, i) to (b, j).

    Lame form of int lambda div u div v + 2 mu eps(u) : eps(v) for u = N_b e_j, v = N_a e_i:
    |T| (lambda g_ai g_bj + mu g_aj g_bi + mu delta_ij g_a . g_b).
    """
    lam, mu = lame_parameters(np.broadcast_to(youngs_modulus, geom.volumes.shape), nu)
    g = geom.grads
    wl, wm = (lam * geom.volumes)[:, None, None, None, None], (mu * geom.volumes)
    K = wl * np.einsum("eai,ebj->eabij", g, g)
    K += wm[:, None, None, None, None] * np.einsum("eaj,ebi->eabij", g, g)
    K += (wm[:, None, None] * np.einsum("eak,ebk->eab", g, g))[..., None, None] * np.eye(3)
    return K


@dataclass(frozen=True)
class ElasticAssembler:
    """Assembles the stiffness of one mesh for any per-tet E: built once per mesh.

    On a uniform Kuhn mesh (``shape_id`` given) every element matrix is E_e K_ref[shape_e], so the
    BSR data is one sparse product ``gather @ K_ref``: ``gather`` (n_blocks, 6*16) holds E of the
    tet that puts combination (shape, a, b) into each block. On a graded Kuhn mesh a tet of cell
    (hx, hy, hz) has K_e = E_e sum_m F_m(e) R_m[shape_e] over the 6 factors |T| / (h_p h_q), p <= q
    (``cell_factors``), so the data is 6 such products. Elsewhere it is 9 bincounts of the
    element matrices over the pattern's slots (memory 16x9 floats per tet: small meshes only).
    """

    pattern: Pattern
    geom: ElementGeometry
    shape_id: np.ndarray | None = None
    gather: sp.csr_matrix | None = None
    gather_tet: np.ndarray | None = None  # tet of each stored entry of ``gather``
    reference_tets: np.ndarray | None = None  # (6,) one tet of each Kuhn shape
    cell_factors: np.ndarray | None = None  # (n_tets, 6) |T| / (h_p h_q) on a graded mesh
    unit_grads: np.ndarray | None = None  # (6, 4, 3) reference gradients on the unit cube

    def stiffness(self, youngs_modulus: np.ndarray | float, nu: float) -> sp.bsr_matrix:
        """Stiffness matrix (3 n_nodes, 3 n_nodes) as BSR 3x3 blocks; E per tet in Pa."""
        n_tets = self.geom.volumes.shape[0]
        E = np.ascontiguousarray(np.broadcast_to(np.asarray(youngs_modulus, float), (n_tets,)))
        if self.gather is not None:
            assert self.gather_tet is not None
            data = self._gathered(self.gather, self.gather_tet, E, nu)
        else:
            K = elastic_local(self.geom, E, nu).reshape(n_tets * 16, 9)
            slot = self.pattern.slot.ravel()
            data = np.column_stack(
                [np.bincount(slot, K[:, c], minlength=self.pattern.nnz) for c in range(9)]
            )
        n = 3 * self.pattern.n
        return sp.bsr_matrix(
            (data.reshape(-1, 3, 3), self.pattern.indices, self.pattern.indptr), shape=(n, n)
        )

    def stiffness_blocks(
        self, youngs_modulus: np.ndarray, nu: float, blocks: np.ndarray
    ) -> np.ndarray | None:
        """The stored 3x3 blocks ``blocks`` (m,) of ``stiffness(E, nu)``, (m, 3, 3), bit for bit
        (each block sums its tets in the same order); None without a gather plan."""
        if self.gather is None:
            return None
        assert self.gather_tet is not None
        g = self.gather
        starts, counts = g.indptr[blocks], g.indptr[blocks + 1] - g.indptr[blocks]
        indptr = np.concatenate([[0], np.cumsum(counts)])
        entries = np.repeat(starts - indptr[:-1], counts) + np.arange(int(indptr[-1]))
        sub = sp.csr_matrix(
            (np.zeros(entries.size), g.indices[entries], indptr), shape=(blocks.size, g.shape[1])
        )
        E = np.ascontiguousarray(youngs_modulus, dtype=float)
        return self._gathered(sub, self.gather_tet[entries], E, nu).reshape(-1, 3, 3)

    def _gathered(
        self, gather: sp.csr_matrix, gather_tet: np.ndarray, E: np.ndarray, nu: float
    ) -> np.ndarray:
        """BSR data (rows of ``gather``, 9) of the Kuhn-mesh stiffness: ``gather`` (its data
        overwritten) maps blocks to (shape, a, b) combinations, ``gather_tet`` its entries' tets."""
        assert self.reference_tets is not None
        if self.cell_factors is None:
            ref = self.reference_tets
            g = ElementGeometry(self.geom.grads[ref], self.geom.volumes[ref])
            K_ref = elastic_local(g, 1.0, nu).reshape(ref.size * 16, 9)
            np.take(E, gather_tet, out=gather.data)
            return gather @ K_ref
        assert self.unit_grads is not None
        R = graded_reference(self.unit_grads, nu)
        by_component = np.zeros((9, gather.shape[0]))
        for m in range(6):  # factor m feeds 3 (diagonal) or 2 (off-diagonal) components
            cols = np.flatnonzero(np.any(R[m] != 0.0, axis=0))
            gather.data[:] = (E * self.cell_factors[:, m])[gather_tet]
            part = gather @ R[m][:, cols]
            for i, c in enumerate(cols):
                by_component[c] += part[:, i]
        # C order: scipy's BSR mat-vec copies a non-contiguous data array on every call
        # (110 ms against 40 ms per K @ u on the fixed-electrode grid)
        return np.ascontiguousarray(by_component.T)


def elastic_assembler(
    pattern: Pattern, geom: ElementGeometry, shape_id: np.ndarray | None = None
) -> ElasticAssembler:
    """Precompute the assembly of ``pattern``; pass the mesh's ``shape_id`` on a Kuhn mesh.

    With ``shape_id`` the tets must be the Kuhn tets of a structured grid (``TetMesh``
    guarantees it): on a uniform grid their element matrices are taken from one reference tet
    per shape, on a graded grid they are scaled from unit-cube references per cell.
    """
    if shape_id is None:
        return ElasticAssembler(pattern, geom)
    sid = np.asarray(shape_id, dtype=np.intp)
    shapes = np.unique(sid)
    order = np.argsort(sid, kind="stable")
    counts = np.bincount(sid)[shapes]
    starts = np.concatenate([[0], np.cumsum(counts)])
    # CSC by combination (shape, a, b): within one column no two tets share a block.
    rows, tet_of = [], []
    for s in range(shapes.size):
        tets_s = order[starts[s] : starts[s + 1]]
        rows.append(pattern.slot[tets_s].reshape(-1, 16).T.ravel())
        tet_of.append(np.tile(tets_s, 16))
    col_ptr = np.concatenate([[0], np.cumsum(np.repeat(counts, 16))])
    index_type = np.int32 if pattern.nnz < 2**31 and sid.size < 2**31 else np.int64
    entry = np.arange(col_ptr[-1], dtype=np.int64)
    csc = sp.csc_matrix(
        (entry, np.concatenate(rows).astype(index_type), col_ptr),
        shape=(pattern.nnz, 16 * shapes.size),
    )
    del rows
    csr = csc.tocsr()  # counting sort by block: linear time
    gather_tet = np.concatenate(tet_of).astype(index_type)[csr.data]
    gather = sp.csr_matrix((np.zeros(csr.nnz), csr.indices, csr.indptr), shape=csr.shape)
    reference_tets = order[starts[:-1]]
    box = 1.0 / np.abs(geom.grads).max(axis=1)  # (n_tets, 3) cell sizes of the Kuhn tets
    ref_box = box[reference_tets][np.searchsorted(shapes, sid)]
    if np.all(np.abs(box - ref_box) <= 1e-9 * ref_box):  # uniform grid
        return ElasticAssembler(pattern, geom, sid, gather, gather_tet, reference_tets)
    factors = np.column_stack([geom.volumes / (box[:, p] * box[:, q]) for p, q in _FACTOR_PAIRS])
    unit = np.rint(geom.grads[reference_tets] * box[reference_tets][:, None, :])
    return ElasticAssembler(pattern, geom, sid, gather, gather_tet, reference_tets, factors, unit)


_FACTOR_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
_FACTOR_OF = np.array([[0, 3, 4], [3, 1, 5], [4, 5, 2]])  # factor index of axis pair (p, q)


def graded_reference(unit_grads: np.ndarray, nu: float) -> np.ndarray:
    """Reference matrices R (6, n_ref * 16, 9) of the graded Kuhn stiffness at E = 1.

    With unit-cube gradients u (n_ref, 4, 3), a tet of cell h has g = u / h, so
    |T| (lambda g_ai g_bj + mu g_aj g_bi) = F_(ij) (lambda u_ai u_bj + mu u_aj u_bi) and
    |T| mu delta_ij g_a . g_b = mu delta_ij sum_k F_(kk) u_ak u_bk, with F_(pq) = |T| / (h_p h_q).
    """
    lam, mu = lame_parameters(1.0, nu)
    u = unit_grads
    n_ref = u.shape[0]
    R = np.zeros((6, n_ref, 4, 4, 3, 3))
    for i in range(3):
        for j in range(3):
            R[_FACTOR_OF[i, j], ..., i, j] += lam * np.einsum("ea,eb->eab", u[..., i], u[..., j])
            R[_FACTOR_OF[i, j], ..., i, j] += mu * np.einsum("ea,eb->eab", u[..., j], u[..., i])
    for k in range(3):
        uu = mu * np.einsum("ea,eb->eab", u[..., k], u[..., k])
        for i in range(3):
            R[_FACTOR_OF[k, k], ..., i, i] += uu
    return R.reshape(6, n_ref * 16, 9)


def eigenstress_load(
    geom: ElementGeometry,
    tets: np.ndarray,
    n_nodes: int,
    pressure_excess_pa: np.ndarray,
    tet_weight: np.ndarray | None = None,
    *,
    touching: np.ndarray | None = None,
) -> np.ndarray:
    """Nodal force (n_nodes, 3) in N of an isotropic eigenstress: int (p - p0) div v.

    ``pressure_excess_pa`` is the nodal p - p0 (n_nodes,); P1 integrated exactly against the
    constant div v of a tet: |T| mean_T(p - p0) grad N_a. ``tet_weight`` (n_tets,) scales the
    eigenstress per tet (0 where there is no tissue to carry a pore pressure). ``touching``:
    indices of tets that include every tet with a node where p - p0 is not zero (for example
    ``TetMesh.tets_touching``); only those are summed: a few thousand of a million while the
    tissue boils, instead of a gather over every tet.
    """
    dp = np.asarray(pressure_excess_pa, dtype=float)
    if touching is not None:
        tets = tets[touching]
        vol, grads = geom.volumes[touching], geom.grads[touching]
        weight = None if tet_weight is None else np.asarray(tet_weight)[touching]
    else:
        vol, grads, weight = geom.volumes, geom.grads, tet_weight
    q = vol * (dp[tets] @ np.full(4, 0.25))
    if weight is not None:
        q = q * weight
    idx = tets.ravel()
    return np.column_stack(
        [
            np.bincount(idx, (q[:, None] * grads[:, :, i]).ravel(), minlength=n_nodes)
            for i in range(3)
        ]
    )


def displacement_gradient(geom: ElementGeometry, tets: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Per-tet displacement gradient (n_tets, 3, 3), [e, i, k] = du_i / dx_k, of nodal u (n, 3)."""
    return np.einsum("eai,eak->eik", u[tets], geom.grads)


def strain(geom: ElementGeometry, tets: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Per-tet small strain (n_tets, 3, 3) of nodal displacements u (n_nodes, 3) in m."""
    G = displacement_gradient(geom, tets, u)
    return 0.5 * (G + np.swapaxes(G, 1, 2))


def rigid_body_modes(points: np.ndarray) -> np.ndarray:
    """The 6 rigid-body modes (3 n_nodes, 6): 3 translations, 3 rotations about the centroid.

    Rotations are scaled by the body's size so all columns have comparable norms.
    """
    x = points - points.mean(axis=0)
    x = x / max(float(np.abs(x).max()), np.finfo(float).tiny)
    n = points.shape[0]
    B = np.zeros((n, 3, 6))
    B[:, 0, 0] = B[:, 1, 1] = B[:, 2, 2] = 1.0
    B[:, 0, 3], B[:, 1, 3] = -x[:, 1], x[:, 0]  # about z
    B[:, 1, 4], B[:, 2, 4] = -x[:, 2], x[:, 1]  # about x
    B[:, 2, 5], B[:, 0, 5] = -x[:, 0], x[:, 2]  # about y
    return B.reshape(3 * n, 6)
