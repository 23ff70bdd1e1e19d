"""The windowed polish: PCG on the nodes around the step's change, the rest of the block held.

After the Ritz-scaled, patch-corrected prediction the error left lies around the crater: on the
default graded grid's cutting steps 97-99 % of its energy within 16 mm of the patch (2.7-3.4 k of
37 k nodes; docs/realtime.md). A correction delta that is zero outside a window W and solves
K_WW delta_W = r_W (r the prediction's residual) minimises the global energy-norm error over all
such corrections, so PCG on the window's block, from zero, can only lower it, at the window's
cost instead of the block's; the global energy guard (``fem.energy_cg``) still decides whether
the answer is accepted. The window and its AMG hierarchy are kept while the change stays inside
its inner box (a new hierarchy costs a few global V-cycles), like the global hierarchy is kept
across topologies: a stale preconditioner only slows PCG.
The window's history (solving for past displacements with it): ``window_history``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from pyamg.multilevel import MultilevelSolver

from diathermy.fem.energy_cg import EnergyCG, energy_cg
from diathermy.fem.multigrid import deterministic_sa, v_cycle_preconditioner
from diathermy.fem.window_box import WindowBox, choose_box, nodes_in_box
from diathermy.physics.local_solve import WINDOW_MAX_FRACTION, IncrementalSettings
from diathermy.physics.mechanics import DEFAULT_AMG_OPTIONS, MechanicsSolver
from diathermy.physics.patch_correction import block_rows_plan
from diathermy.physics.window_history import History, augmented_correct


def block_submatrix_plan(
    indptr: np.ndarray, indices: np.ndarray, nodes: np.ndarray, n_nodes: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the block submatrix on ``nodes`` (ascending) lies in a block pattern (indptr,
    indices) of n_nodes block rows: (positions of its blocks in the data, its indptr, its
    indices), so that its data is ``data[positions]`` for any matrix on that pattern."""
    local = np.full(n_nodes, -1, dtype=np.int64)
    local[nodes] = np.arange(nodes.size)
    rows_pos, row_of = block_rows_plan(indptr, nodes)
    cols = local[indices[rows_pos]]
    keep = cols >= 0
    sub_indptr = np.zeros(nodes.size + 1, dtype=np.int64)
    np.cumsum(np.bincount(row_of[keep], minlength=nodes.size), out=sub_indptr[1:])
    return rows_pos[keep], sub_indptr, cols[keep]


@dataclass
class PolishWindow:
    """A window of whole nodes on a 3x3-block pattern, with the AMG hierarchy of its block.

    ``built_E``, ``built_healthy``: the topology the hierarchy was built for (a checkpoint
    stores them, so a restored run rebuilds the same preconditioner).
    """

    box: WindowBox
    nodes: np.ndarray
    positions: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    pattern: np.ndarray  # the global block pattern's indices the plan was made for
    ring: tuple[np.ndarray, np.ndarray, np.ndarray]  # ``ring_plan`` of the window
    preconditioner: spla.LinearOperator
    built_E: np.ndarray
    built_healthy: np.ndarray
    hierarchy: MultilevelSolver  # the preconditioner's; its fine level follows ``operator``

    @property
    def dofs(self) -> np.ndarray:
        """The window's DOFs (3 per node) in the global numbering."""
        return (3 * self.nodes[:, None] + np.arange(3)).ravel()

    def fits(self, A: sp.bsr_matrix) -> bool:
        """Whether A is on the pattern this window's plan was made for."""
        return A.indices is self.pattern or (
            A.indices.shape == self.pattern.shape and np.array_equal(A.indices, self.pattern)
        )

    def matrix(self, A: sp.bsr_matrix) -> sp.bsr_matrix:
        """The window's block of A (the same pattern as when the window was made)."""
        n = 3 * self.nodes.size
        return sp.bsr_matrix((A.data[self.positions], self.indices, self.indptr), shape=(n, n))

    def operator(self, A: sp.bsr_matrix) -> sp.bsr_matrix:
        """The window's block of A, also made the fine level of its V-cycle: the smoother and
        the restricted residual see the operator PCG solves, not the one the hierarchy was
        built for (the prolongators and coarse operators stay). On the fixed electrode's
        0.4 mm cutting steps, with the history, 14-25 window iterations instead of 18-34 as the
        kept hierarchy aged; a fresh hierarchy took 10-20 (docs/realtime.md)."""
        Aw = self.matrix(A)
        self.hierarchy.levels[0].A = Aw
        return Aw

    def spread(
        self, A: sp.bsr_matrix, delta: np.ndarray, Aw: sp.bsr_matrix | None = None
    ) -> np.ndarray:
        """A @ d (all DOFs) for d = ``delta`` (the window's DOFs) and 0 elsewhere, not a global
        mat-vec: the window's block (``Aw``, this step's ``matrix(A)``, when the caller has it)
        on its own rows, and the blocks of the ring of nodes next to it on theirs."""
        if Aw is None:
            Aw = self.matrix(A)
        positions, ring_rows, ring_cols = self.ring
        d = np.reshape(delta, (-1, 3))
        n = A.shape[0] // 3
        out = np.zeros((n, 3))
        out[self.nodes] = np.reshape(Aw @ np.ravel(delta), (-1, 3))
        Ad = np.einsum("bij,bj->bi", A.data[positions], d[ring_cols])
        for i in range(3):
            out[:, i] += np.bincount(ring_rows, Ad[:, i], minlength=n)
        return out.ravel()


def ring_plan(
    indptr: np.ndarray, indices: np.ndarray, nodes: np.ndarray, n_nodes: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The blocks of a block pattern (indptr, indices) of n_nodes block rows that couple a node
    outside ``nodes`` (ascending) to one inside: (their positions in the data, their global
    block row, their column's index in ``nodes``)."""
    local = np.full(n_nodes, -1, dtype=np.int64)
    local[nodes] = np.arange(nodes.size)
    rows_pos, _ = block_rows_plan(indptr, nodes)
    cols = indices[rows_pos]
    ring = np.unique(cols[local[cols] < 0])  # the pattern is symmetric: rows that reach in
    pos, row_of = block_rows_plan(indptr, ring)
    inside = local[indices[pos]]
    keep = inside >= 0
    return pos[keep], ring[row_of[keep]], inside[keep]


def build_window(
    A: sp.bsr_matrix,
    near_nullspace: np.ndarray | None,
    points: np.ndarray,
    box: WindowBox,
    amg_options: dict,
    built_E: np.ndarray,
    built_healthy: np.ndarray,
) -> PolishWindow:
    """The window of the nodes in ``box`` on the 3x3-block operator A (Jacobi-scaled, constrained
    rows unit), with a smoothed-aggregation hierarchy of its block (``amg_options``)."""
    if A.blocksize != (3, 3):
        raise ValueError(f"the windowed polish needs a 3x3-block operator, got {A.blocksize}")
    nodes = nodes_in_box(points, box.lo, box.hi)
    if nodes.size == 0:
        raise ValueError("the polish window holds no node")
    positions, indptr, indices = block_submatrix_plan(A.indptr, A.indices, nodes, points.shape[0])
    n = 3 * nodes.size
    Aw = sp.bsr_matrix((A.data[positions], indices, indptr), shape=(n, n))
    dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
    B = None if near_nullspace is None else np.ascontiguousarray(near_nullspace[dofs])
    ml = deterministic_sa(Aw, B, amg_options)
    return PolishWindow(
        box,
        nodes,
        positions,
        indptr,
        indices,
        A.indices,
        ring_plan(A.indptr, A.indices, nodes, points.shape[0]),
        v_cycle_preconditioner(ml),
        built_E.copy(),
        built_healthy.copy(),
        ml,
    )


def window_correct(
    window: PolishWindow,
    A: sp.bsr_matrix,
    residual: np.ndarray,
    norm_sq: float,
    *,
    tol: float,
    maxiter: int,
) -> EnergyCG:
    """PCG on the window's block for the correction delta_W of an answer with ``residual``
    (the scaled system's b - A x, all DOFs): from zero until the energy-error estimate relative
    to ``norm_sq`` (the whole answer's x.A x) is at most ``tol``, or ``maxiter`` iterations."""
    dofs = window.dofs
    return energy_cg(
        window.operator(A),
        residual[dofs],
        np.zeros(dofs.size),
        window.preconditioner,
        tol=tol,
        maxiter=maxiter,
        norm_sq=norm_sq,
    )


class WindowedPolish:
    """An incremental backend's windowed polish: its kept window and the PCG on it
    (``IncrementalSettings.window_m`` and the window knobs)."""

    def __init__(self, settings: IncrementalSettings) -> None:
        self.settings = settings
        self.window: PolishWindow | None = None

    def correct(
        self,
        solver: MechanicsSolver,
        f: np.ndarray,
        u: np.ndarray,
        Ku: np.ndarray | None,
        change: np.ndarray,
        extra: dict[str, float | int | bool | str],
        history: Sequence[np.ndarray] = (),
        K_newest: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """u (n_nodes, 3) m corrected by PCG on a window around the nodes ``change`` (the
        patch), the rest held (bit for bit), its residual on the scaled system (None: not
        known) and the window's nodes; u as is (and no nodes) when there is no window to solve
        on. ``Ku``: K u (n_nodes, 3) N when known, f the load (n_nodes, 3) N; what it did goes
        into ``extra``. ``history``: past displacements (n_nodes, 3) m whose span is solved
        for with the window (``augmented_correct``); u then moves everywhere (nodes None).
        ``K_newest``: K times the newest of them (n_nodes, 3) N when known."""
        A = solver.krylov.A
        st = self.settings
        if (
            st.window_m == 0
            or st.polish_iterations == 0
            or solver.krylov.kept_preconditioner is None  # no global guard to check it
            or change.size == 0
            or not isinstance(A, sp.bsr_matrix)
            or A.blocksize != (3, 3)
        ):
            return u, None, np.zeros(0, dtype=np.int64)
        t0 = time.perf_counter()
        points = solver.mesh.points
        lo, hi = points[change].min(axis=0), points[change].max(axis=0)
        w = self.window
        built = w is None or not w.box.holds(lo, hi) or not w.fits(A)
        if built:
            max_nodes = int(WINDOW_MAX_FRACTION * solver.mesh.n_nodes)
            w = self.build(solver, choose_box(points, change, st.window_m, max_nodes))
        assert w is not None
        s = solver.scale
        x0 = u.ravel() / s
        b = f.ravel() * s
        # the scaled residual s (f - K u) from the patch's K u: no global mat-vec
        r = b - A @ x0 if Ku is None else s * (f.ravel() - Ku.ravel())
        tol = st.window_share * st.energy_tolerance
        norm_sq = float(x0 @ (b - r))
        first = None if K_newest is None else s * K_newest.ravel()
        hist = History.of(A, s, history, w, first, solver.constrained) if len(history) else None
        if hist is None or hist.size == 0:
            res = window_correct(w, A, r, norm_sq, tol=tol, maxiter=st.window_iterations)
            c = None
        else:
            res, c = augmented_correct(
                w, A, hist, r, norm_sq, tol=tol, maxiter=st.window_iterations
            )
        if res.estimate > tol:
            self.window = None  # stale for this change: the next step builds a new one
        dofs = w.dofs
        # both solves above made the window's block of A its V-cycle's fine level this step
        r_new = r - w.spread(A, res.x, w.hierarchy.levels[0].A)
        if c is None or hist is None:  # the rest held, bit for bit
            corrected = u.ravel().copy()
            corrected[dofs] = (x0[dofs] + res.x) * s[dofs]
        else:
            x = x0 + hist.Z @ c
            x[dofs] += res.x
            corrected = x * s
            r_new -= hist.AZ @ c
        extra.update(
            window_nodes=int(w.nodes.size),
            window_built=built,
            window_iterations=res.iterations,
            window_estimate=res.estimate,
            window_history=0 if hist is None else hist.size,
            window_s=time.perf_counter() - t0,
        )
        return corrected.reshape(-1, 3), r_new, w.nodes if c is None else None

    def build(self, solver: MechanicsSolver, box: WindowBox) -> PolishWindow:
        """A new window on ``box`` for ``solver``'s operator, kept as ``self.window``."""
        A = solver.krylov.A
        if not isinstance(A, sp.bsr_matrix):
            raise ValueError("the windowed polish needs the solver's block operator")
        self.window = build_window(
            A,
            solver.krylov.near_nullspace,
            solver.mesh.points,
            box,
            DEFAULT_AMG_OPTIONS,
            solver.youngs_modulus_pa,
            solver.healthy,
        )
        return self.window

    def restore(self, solver: MechanicsSolver, box: np.ndarray) -> None:
        """The window a checkpoint saved: its box (4, 3) m on ``solver``, the operator of the
        topology its hierarchy was built for."""
        self.build(solver, WindowBox.from_array(box))
