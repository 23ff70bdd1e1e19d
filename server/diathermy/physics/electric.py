"""Quasi-static electric potential and Joule heat (PHYSICS.md sections 1-2); the drive that sets
the injected current is in ``driven_potential``.

div(sigma grad V) = 0 with V = 0 on the bottom (z-), -sigma dV/dn = j on the electrode's contact
disk and insulated elsewhere. The contact load is a quadrature of the disk itself, so the
injected current is j * area at every resolution, also when the disk is smaller than a cell.

Dirichlet nodes are eliminated (the solve runs on the free nodes only), so the matrix stays SPD;
it is assembled from edge weights (7-point stencil on the Kuhn mesh) once per conductivity,
scaled to a unit diagonal (robust AMG where a cut puts sigma 1e-5 beside 0.33, see
``fem.multigrid``) and solved by AMG-preconditioned CG with hierarchy reuse and warm starts.
rtol is the relative residual of the scaled system.

Solver tolerance: rtol 1e-8 (relative residual) by default. The discrete energy identity
sum_e q_e |T_e| = V.K.V = int j V holds exactly for CG from zero (Galerkin: the residual is
orthogonal to the iterate) and, after a warm start, to the size of the update's residual:
measured at 33x33x65 after a 0.37 mm electrode move, rtol 1e-6 / 1e-8 / 1e-10 take 9 / 12 / 16
iterations and give identity errors 5e-9 / 4e-11 / 7e-13 and max errors in V of 2e-8 / 3e-10 /
2e-12 (relative). 1e-8 keeps two decades of margin for harder (cut, high-contrast) sigma.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.sparse as sp

from diathermy.errors import SceneError
from diathermy.fem.direct import spd_factor
from diathermy.fem.edge_update import EdgeIncidence, edge_incidence, update_laplacian
from diathermy.fem.edges import EdgeStiffness, LaplacianPattern, laplacian_pattern
from diathermy.fem.energy_cg import EnergyCG, energy_cg
from diathermy.fem.multigrid import SCALAR_AMG_OPTIONS, scaled_candidates, unit_diagonal
from diathermy.fem.solvers import KrylovSolver, ReuseState, SolveStats
from diathermy.fem.window_box import choose_box, nodes_in_box
from diathermy.mesh import Grid, TetMesh
from diathermy.mesh.kuhn_fields import axis_differences, per_tet, shape_gradient, shapes_last


def joule_heat(grid: Grid, sigma: np.ndarray | float, V: np.ndarray) -> np.ndarray:
    """Joule heat q = sigma |grad V|^2 per tet (n_tets,) in W/m^3 of the Kuhn mesh of ``grid``.

    sigma per tet (n_tets,) or one number in S/m; V (n_nodes,) in V. The gradient of each tet
    from node differences (``mesh.kuhn_fields``), no gather and no stored gradient matrix.
    """
    diffs = axis_differences(V, grid)
    sig = per_tet(sigma, grid)
    out = np.empty((6, *sig.shape[:3]))
    for s in range(6):
        gx, gy, gz = shape_gradient(diffs, s)
        np.multiply(gx, gx, out=out[s])
        out[s] += gy * gy
        out[s] += gz * gz
        out[s] *= sig[..., s]
    return shapes_last(out)


def delivered_power(load: np.ndarray, V: np.ndarray) -> float:
    """Electrical power int j V over the contact in W: nodal current load (n_nodes,) in A . V."""
    return float(np.dot(load, V))


@dataclass(frozen=True)
class PotentialStats:
    """One potential solve: Krylov stats, assembly time, and whether a cached field was reused."""

    iterations: int
    residual: float
    assembly_s: float
    setup_s: float
    solve_s: float
    reassembled: bool
    cached: bool
    energy_estimate: float | None = None  # set when the energy guard accepted the answer
    window_nodes: int = 0  # the guarded start's window (``PotentialSolver.window_m``)


WINDOW_MAX_NODES = 4000
"""The largest window the potential's start is corrected on (a sparse LU: about 2 ms for 256
nodes, 40-50 ms for 2.6-3.2 k, 70-120 ms for 4 k, measured on the graded grids' cutting steps)."""

WINDOW_HOT = 1e-3
"""The window covers the nodes whose start residual is above this fraction of the largest."""

UPDATE_MAX_TETS = 0.05
"""A conductivity change updates the last matrix when at most this fraction of the tets changed
(a cutting step changes a few dozen); above it the matrix is assembled anew."""


class PotentialSolver:
    """-div(sigma grad V) = load on the free nodes, V given on ``dirichlet_nodes``.

    The operator is assembled once per conductivity (``set_conductivity`` compares with the
    last one); the AMG hierarchy and the last solution (a warm start) are kept between solves.

    Args:
        mesh: the tet mesh.
        stiffness: its edge couplings (``diathermy.fem.edges.edge_stiffness``).
        dirichlet_nodes: nodes with prescribed V (default: the bottom side z-).
        rtol: relative residual of the CG solve.
        stale_factor, max_stale_solves: when a conductivity change keeps the AMG hierarchy of
            an older one (``KrylovSolver``); a checkpoint saves its origin (``hierarchy_sigma``).
        energy_tolerance: accept the PCG iterate from the last solution with the kept hierarchy
            once its estimated relative energy-norm error (``fem.energy_cg``) is at most this,
            within ``energy_maxiter`` iterations; else (and when None) solve to ``rtol``.
        window_m: before that PCG, correct the last solution exactly on the nodes around its
            residual (those above ``WINDOW_HOT`` of the largest) grown by this margin in m,
            the margin halved until at most ``WINDOW_MAX_NODES`` nodes (0: no window). A
            conductivity change is local (the crater, the contact): on the graded grids'
            cutting steps 98-99.7 % of the start's error energy lies within 2 mm of it, and
            the window's sparse LU saves most of the PCG iterations (docs/realtime.md).
    """

    def __init__(
        self,
        mesh: TetMesh,
        stiffness: EdgeStiffness,
        *,
        dirichlet_nodes: np.ndarray | None = None,
        rtol: float = 1e-8,
        amg_options: dict[str, Any] | None = None,
        stale_factor: float = 1.5,
        max_stale_solves: int = 0,
        energy_tolerance: float | None = None,
        energy_maxiter: int = 30,
        window_m: float = 0.0,
    ) -> None:
        self.energy_tolerance = energy_tolerance
        self.energy_maxiter = energy_maxiter
        self.window_m = float(window_m)
        self._window_nodes = 0
        fixed = mesh.side_nodes("z-") if dirichlet_nodes is None else np.unique(dirichlet_nodes)
        free = np.setdiff1d(np.arange(mesh.n_nodes), fixed)
        self.stiffness = stiffness
        self.n_tets = mesh.n_tets
        self.fixed = fixed
        self.pattern: LaplacianPattern = laplacian_pattern(stiffness, free)
        self._free_points = mesh.points[self.pattern.nodes]
        opts = SCALAR_AMG_OPTIONS if amg_options is None else amg_options
        # a cut changes sigma locally: the old hierarchy stays a good preconditioner (measured at
        # 33x33x65: 13 -> 14..19 iterations as a trench deepens, against a 2x-solve setup)
        self.krylov = KrylovSolver(
            "potential",
            rtol=rtol,
            amg_options=opts,
            stale_factor=stale_factor,
            max_stale_solves=max_stale_solves,
            # the last potential as is: Ritz-scaled it took 44 CG iterations against 33 on the
            # graded 0.5 mm cut (benchmarks/results/realtime_solvers.md, same fresh hierarchies)
            ritz=False,
        )
        self.hierarchy_sigma: np.ndarray | None = None  # the conductivity the AMG was built for
        self.sigma: np.ndarray | None = None
        self.weights: np.ndarray | None = None
        self.matrix: sp.csr_matrix | None = None  # K on the free nodes, unscaled
        self._scaled: sp.csr_matrix | None = None  # its unit-diagonal scaling
        self._scale = np.ones(self.pattern.n)  # d = diag(K)^-1/2
        self.version = 0  # counts assemblies, so cached fields can tell whether sigma changed
        self._incidence: EdgeIncidence | None = None  # built on the first update
        self._pending_assembly_s = 0.0

    @property
    def free(self) -> np.ndarray:
        return self.pattern.nodes

    def set_conductivity(self, sigma: np.ndarray | float) -> bool:
        """Use conductivity sigma (n_tets,) in S/m; reassembles only if it changed. True if it did."""
        sigma = np.broadcast_to(np.asarray(sigma, dtype=float), (self.n_tets,))
        if self.sigma is not None and np.array_equal(self.sigma, sigma):
            return False
        if not np.all(sigma > 0) or not np.all(np.isfinite(sigma)):
            raise SceneError("conductivity must be positive and finite in every tet")
        t0 = time.perf_counter()
        scaled = self._updated(sigma)
        if scaled is None:
            self.weights = self.stiffness.weights(sigma)
            self.matrix = self.pattern.matrix(self.stiffness, self.weights)
            scaled, self._scale = unit_diagonal(self.matrix)
        self._scaled = scaled
        self.sigma = sigma.copy()
        self.version += 1
        self.krylov.near_nullspace = scaled_candidates(self._scale)
        self.krylov.set_operator(scaled)
        self._pending_assembly_s += time.perf_counter() - t0
        return True

    def _updated(self, sigma: np.ndarray) -> sp.csr_matrix | None:
        """The scaled matrix for ``sigma`` from the last one, its entries rewritten where the
        tets whose sigma changed couple (``fem.edge_update``: bit for bit a fresh assembly's),
        with ``weights``, ``matrix`` and the scale set; None when there is no last matrix or
        more than ``UPDATE_MAX_TETS`` of the tets changed (assembled anew)."""
        A = self._scaled
        if self.sigma is None or self.matrix is None or self.weights is None or A is None:
            return None
        changed = np.flatnonzero(sigma != self.sigma)
        if changed.size > UPDATE_MAX_TETS * self.n_tets:
            return None
        if self._incidence is None:
            self._incidence = edge_incidence(self.stiffness, self.n_tets, self.pattern)
        inc = self._incidence
        edges = inc.edges_of_tets(changed)
        w = self.weights.copy()
        w[edges] = inc.weights_on(self.stiffness, sigma, edges)
        nodes = np.unique(self.stiffness.edges[edges])
        up = update_laplacian(
            self.pattern,
            inc,
            self.matrix.data,
            A.data,
            self._scale,
            w,
            edges,
            nodes,
            inc.degree_on(w, nodes),
        )
        p = self.pattern
        self.weights, self._scale = w, up.scale
        self.matrix = sp.csr_matrix((up.data, p.indices, p.indptr), shape=(p.n, p.n))
        return sp.csr_matrix((up.scaled_data, p.indices, p.indptr), shape=(p.n, p.n))

    def solve(
        self, load: np.ndarray, dirichlet_values: np.ndarray | None = None
    ) -> tuple[np.ndarray, PotentialStats]:
        """V (n_nodes,) for a nodal load (n_nodes,) in A; dirichlet_values (n_fixed,) default 0."""
        if self.weights is None:
            raise SceneError("potential: set_conductivity before solve")
        t0 = time.perf_counter()
        V = np.zeros(self.stiffness.n_nodes)
        b = load[self.free].astype(float, copy=True)
        if dirichlet_values is not None:
            V[self.fixed] = dirichlet_values
            b -= self._lift(V)
        bs = self._scale * b
        guarded = self._energy_guarded(bs)
        if guarded is not None and guarded.estimate <= (self.energy_tolerance or 0.0):
            self.krylov.warm_start = guarded.x
            V[self.free] = self._scale * guarded.x
            stats = PotentialStats(
                guarded.iterations,
                guarded.residual,
                self._pending_assembly_s,
                0.0,
                time.perf_counter() - t0,
                self._pending_assembly_s > 0,
                False,
                energy_estimate=guarded.estimate,
                window_nodes=self._window_nodes,
            )
            self._pending_assembly_s = 0.0
            return V, stats
        y, st = self.krylov.solve(bs, None if guarded is None else guarded.x)
        if st.rebuilt:
            self.hierarchy_sigma = self.sigma
        V[self.free] = self._scale * y
        stats = _stats(st, self._pending_assembly_s, reassembled=self._pending_assembly_s > 0)
        if guarded is not None:
            its = guarded.iterations + stats.iterations
            stats = replace(stats, iterations=its, solve_s=time.perf_counter() - t0)
        self._pending_assembly_s = 0.0
        return V, stats

    def _energy_guarded(self, b: np.ndarray) -> EnergyCG | None:
        """PCG on the scaled system from the last potential with the kept hierarchy until the
        energy-error estimate reaches ``energy_tolerance`` (None: no guard, nothing to start
        from, or no hierarchy to keep; the full solve then runs as before)."""
        M, x0, A = self.krylov.kept_preconditioner, self.krylov.warm_start, self.krylov.A
        if self.energy_tolerance is None or M is None or A is None or x0 is None:
            return None
        if x0.shape != b.shape:
            return None
        x0, r = self._window_corrected(A, b, x0)
        return energy_cg(
            A, b, x0, M, tol=self.energy_tolerance, maxiter=self.energy_maxiter, residual=r
        )

    def _window_corrected(
        self, A: sp.csr_matrix, b: np.ndarray, x0: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """(x, b - A x): x0 plus the exact correction on the window around its residual
        (``window_m``), A_WW d = r_W, the rest held; x0 itself when there is no window (off, no
        residual). The residual is updated from the window's own rows (A is symmetric), so the
        window costs one global mat-vec; None when none was computed."""
        self._window_nodes = 0
        if self.window_m <= 0:
            return x0, None
        r = b - A @ x0
        peak = float(np.abs(r).max(initial=0.0))
        if not peak > 0:
            return x0, r
        hot = np.flatnonzero(np.abs(r) > WINDOW_HOT * peak)
        box = choose_box(self._free_points, hot, self.window_m, WINDOW_MAX_NODES)
        W = nodes_in_box(self._free_points, box.lo, box.hi)
        if W.size > WINDOW_MAX_NODES:  # the change itself spans more: PCG over the block
            return x0, r
        rows = A[W]
        d = spd_factor(rows[:, W]).solve(r[W])  # a block of the SPD scaled operator
        x = x0.copy()
        x[W] += d
        self._window_nodes = int(W.size)
        return x, r - rows.T @ d

    def restore_hierarchy(self, sigma: np.ndarray, reuse: ReuseState) -> None:
        """Rebuild the AMG hierarchy of conductivity sigma (n_tets,) S/m with its reuse counters
        (as a checkpoint saved them), so the next solves repeat the original run's."""
        self.set_conductivity(sigma)
        self.krylov.build()
        self.krylov.reuse = reuse
        self.hierarchy_sigma = self.sigma

    def dissipation(self, V: np.ndarray) -> float:
        """int sigma |grad V|^2 dV in W of a potential V (n_nodes,) in V: V^T K V summed over the
        mesh edges, sum w_ij (V_i - V_j)^2. Exactly the Joule heat the thermal step receives,
        whatever the solve's accuracy; for the exact solution it equals the contact's load . V."""
        if self.weights is None:
            raise SceneError("potential: set_conductivity before dissipation")
        i, j = self.stiffness.edges[:, 0], self.stiffness.edges[:, 1]
        dV = V[i] - V[j]
        return float(self.weights @ (dV * dV))

    def _lift(self, V: np.ndarray) -> np.ndarray:
        """K_fD V_D on the free nodes: what the prescribed values push into the free rows."""
        assert self.weights is not None
        edges, loc, n = self.stiffness.edges, self.pattern.local, self.pattern.n
        out = np.zeros(n)
        for a, b in ((0, 1), (1, 0)):
            rows, cols = edges[:, a], edges[:, b]
            sel = (loc[rows] >= 0) & (loc[cols] < 0)
            out -= np.bincount(loc[rows[sel]], self.weights[sel] * V[cols[sel]], minlength=n)
        return out


def _stats(st: SolveStats, assembly_s: float, *, reassembled: bool) -> PotentialStats:
    return PotentialStats(
        iterations=st.iterations,
        residual=st.residual,
        assembly_s=assembly_s,
        setup_s=st.setup_s,
        solve_s=st.solve_s,
        reassembled=reassembled,
        cached=False,
    )
