"""Elastostatics with the pore pressure as an eigenstress (PHYSICS.md section 2).

div sigma = 0, sigma = C : eps(u) - (p - p0) I; weak form int eps(v) : C : eps(u) = int (p - p0)
div v. Dirichlet constraints per DOF (the bottom clamped by default), traction-free elsewhere,
the cut surface included. Cut tissue keeps an ersatz modulus and carries no pore pressure.

``MechanicsSolver`` is built once per topology (mesh, per-tet E, nu, constraints) and then solves
for many pressure fields: its AMG hierarchy (smoothed aggregation on 3x3 blocks, rigid-body modes
as near-nullspace) is reused and every solve starts from the previous displacement.

Loose fragments: a face-connected component of healthy tets whose constrained DOFs do not fix
all 6 rigid-body modes floats on the ersatz material alone. By default such a fragment is
*removed*: it takes the ersatz modulus and drops its eigenstress, exactly as if it had been cut
away (PHYSICS.md section 4: detached tissue leaves the block), so the operator stays as well
conditioned as after any cut and the result says which tets were removed (``loose``) so the
level set can mark them. ``loose_fragments="keep"`` leaves the fragment elastic and loaded; it is
then held only by the ersatz material (1e-6 E), which is nonsingular but slows CG.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import partial
from typing import Any, Literal

import numpy as np
import scipy.sparse as sp

from diathermy.errors import SceneError
from diathermy.fem.bsr_blocks import block_rows, constrain_blocks, constrain_in_place, scale_blocks
from diathermy.fem.elastic import (
    ElasticAssembler,
    eigenstress_load,
    elastic_assembler,
    rigid_body_modes,
)
from diathermy.fem.geometry import ElementGeometry, structured_geometry
from diathermy.fem.solvers import KrylovSolver
from diathermy.fem.sparsity import build_pattern
from diathermy.mesh import TetMesh
from diathermy.physics.constraints import Constraints, clamped_bottom
from diathermy.physics.fragments import Fragments, find_fragments, update_fragments

_CHEBYSHEV = ("chebyshev", {"degree": 1})
"""Degree 1: a V-cycle of about 4 fine-level mat-vecs against 8 with degree 3. A full solve takes
about twice the CG iterations at the same or lower cost; the incremental mode's polish, a few
iterations from a close start each step, takes about 35 % less mechanics time per cutting step
on the graded grids with a 3e-3 energy tolerance (docs/realtime.md, 2026-12-03)."""
DEFAULT_AMG_OPTIONS: dict[str, Any] = {
    "presmoother": _CHEBYSHEV,
    "postsmoother": _CHEBYSHEV,
    "max_coarse": 64,
    "coarse_solver": "cholesky",
}
"""Smoothed aggregation for the 3x3-block elasticity matrix (measured in benchmarks/mechanics.py).
The coarsest level is factored (``fem.multigrid.coarse_solver``): pyamg's pseudo-inverse, formed
again after every cut, took ~16 ms a cutting step on the default graded grid (up to 140 ms with a
threaded OpenBLAS), the factor ~0.5 ms."""
MAX_UPDATED_TETS = 0.05
"""A new topology updates the previous stiffness when at most this fraction of tets changed E
(a cut step changes a few dozen); above it assembling anew is as cheap."""


@dataclass(frozen=True)
class MechanicsStats:
    """What one mechanics solve did (times in s)."""

    iterations: int
    residual: float
    load_s: float
    amg_setup_s: float
    solve_s: float
    rebuilt: bool
    stale: bool = False  # preconditioned by the hierarchy of an earlier topology


@dataclass(frozen=True)
class MechanicsResult:
    """Nodal displacement u (n_nodes, 3) in m, and how it was obtained."""

    u: np.ndarray
    stats: MechanicsStats


def scaled_near_nullspace(
    rigid_modes: np.ndarray, scale: np.ndarray, constrained: np.ndarray
) -> np.ndarray:
    """The rigid-body modes (3 n_nodes, 6) seen by the Jacobi-scaled system (x = u / scale),
    zero on the constrained DOFs: the near-nullspace of its AMG hierarchy."""
    B = rigid_modes / scale[:, None]
    B[constrained] = 0.0
    return B


class MechanicsSolver:
    """The elastic operator of one topology, solved for many pressure fields.

    Args:
        mesh: the tet mesh.
        youngs_modulus_pa: E per tet (n_tets,) or one number; cut tissue at the ersatz level.
        poisson_ratio: nu in (-1, 0.5); up to 0.49 is tested.
        constraints: prescribed DOFs; default ``clamped_bottom(mesh)``.
        healthy: bool (n_tets,) tissue that carries stiffness and pore pressure; default
            E >= 1e-3 max E (the ersatz level is 1e-6 E). Or each tet's share of tissue in
            [0, 1] (``level_set.removal`` 'fraction'): the pore pressure's load is weighted by
            it, and the tets more than half tissue are the healthy ones.
        ersatz_ratio: modulus of removed (loose) tissue relative to max E.
        loose_fragments: "remove" (default) or "keep"; see the module docstring.
        rtol, maxiter, amg_options: for the AMG-preconditioned CG.
        assembler: a prebuilt ``ElasticAssembler`` of this mesh (saves its setup on re-topology).
        krylov: the CG solver of an earlier topology of this mesh: it takes this operator and
            keeps its hierarchy while that pays (``KrylovSolver.stale_factor``); rtol, maxiter
            and amg_options are then its own.
        base: the solver of an earlier topology of this mesh, nu and (zero-valued)
            constraints: the blocks of the tets whose E changed are assembled again and the
            rest of its stiffness is kept; bit for bit the matrix a fresh build gives.
        consume_base: update ``base``'s matrices in place instead of copying them; ``base``
            is then ``consumed`` and can neither solve nor be updated again.
    """

    fragments: Fragments
    healthy: np.ndarray
    _rows: np.ndarray  # block row of each stored block of K
    _rigid_modes: np.ndarray  # rigid_body_modes of the mesh, shared along a chain of updates

    def __init__(
        self,
        mesh: TetMesh,
        youngs_modulus_pa: np.ndarray | float,
        poisson_ratio: float,
        constraints: Constraints | None = None,
        *,
        healthy: np.ndarray | None = None,
        ersatz_ratio: float = 1e-6,
        loose_fragments: Literal["remove", "keep"] = "remove",
        rtol: float = 1e-8,
        maxiter: int = 500,
        amg_options: dict[str, Any] | None = None,
        assembler: ElasticAssembler | None = None,
        krylov: KrylovSolver | None = None,
        base: MechanicsSolver | None = None,
        consume_base: bool = False,
    ) -> None:
        t0 = time.perf_counter()
        self.mesh = mesh
        self.assembler = assembler or mechanics_assembler(mesh)
        self.poisson_ratio = float(poisson_ratio)
        self.constraints = constraints if constraints is not None else clamped_bottom(mesh)
        n_dofs = 3 * mesh.n_nodes
        self.constrained = self.constraints.mask(n_dofs)
        E = np.array(np.broadcast_to(np.asarray(youngs_modulus_pa, float), (mesh.n_tets,)))
        if not np.all(np.isfinite(E)) or np.any(E <= 0):
            raise SceneError("Young's modulus must be positive and finite in every tet")
        if healthy is None:
            healthy = E >= 1e-3 * E.max()
        given = np.asarray(healthy)
        # a share of tissue per tet ('fraction' removal) weights the pore pressure; the tets more
        # than half tissue are the healthy ones of the fragment search
        share = None if given.dtype == bool else np.clip(given.astype(float), 0.0, 1.0)
        healthy = np.asarray(healthy, dtype=bool) if share is None else share > 0.5
        if base is not None and not base.updatable_to(self):
            base = None
        # the mesh's rigid-body modes (3 n_nodes, 6), from the base when there is one
        self._rigid_modes = rigid_body_modes(mesh.points) if base is None else base._rigid_modes
        if base is None and np.linalg.matrix_rank(self._rigid_modes[self.constrained]) < 6:
            raise SceneError("the constraints leave rigid-body motions of the block free")
        # the loose-fragment search of a cut: near the cut when that proves it (see fragments)
        self._centroids: np.ndarray | None = None
        fragments = None
        if base is not None:
            c = base._centroids if base._centroids is not None else mesh.centroids()
            self._centroids = c
            fragments = update_fragments(
                mesh, base.fragments, base.healthy, healthy, self.constrained, c
            )
        if fragments is None:
            fragments = find_fragments(mesh, healthy, self.constrained)
        self.fragments = fragments
        if loose_fragments == "remove" and self.fragments.loose.any():
            E[self.fragments.loose] = ersatz_ratio * E.max()
            healthy = healthy & ~self.fragments.loose
        elif loose_fragments not in ("remove", "keep"):
            raise ValueError(f"loose_fragments must be 'remove' or 'keep', got {loose_fragments!r}")
        self.youngs_modulus_pa = E
        self.healthy = healthy
        # what carries pore pressure: the healthy mask, or the shares with loose fragments at 0
        self.load_weight = healthy if share is None else share
        if share is not None and loose_fragments == "remove":
            self.load_weight[self.fragments.loose] = 0.0
        update = None if base is None else base.updated_stiffness(E, in_place=consume_base)
        self.updated = update is not None
        K, changed_blocks = update if update is not None else (None, None)
        if K is None:
            K = self.assembler.stiffness(E, self.poisson_ratio)
            K_values = np.zeros(n_dofs)
            K_values[self.constraints.dofs] = self.constraints.values
            self._lift = K @ K_values if np.any(K_values) else None
            diag = constrain_in_place(K, self.constrained)
        else:
            self._lift = None
            assert base is not None and changed_blocks is not None
            diag = base.updated_diagonal(K, changed_blocks)
        self._diag = diag
        self._constrained_rhs = diag[self.constraints.dofs] * self.constraints.values
        self.K = K
        # Symmetric Jacobi scaling D^-1/2 K D^-1/2: unit diagonal, so the smoother sees the
        # 1e6 stiffness contrast of the ersatz material as well-scaled rows (see benchmarks).
        self._scale = 1.0 / np.sqrt(diag)
        self._rows = base._rows if base is not None and self.updated else block_rows(K)
        rescaled: np.ndarray | None = None  # the blocks of the scaled K that may have changed
        if base is not None and changed_blocks is not None:
            data, rescaled = base.scaled_data(
                K, self._scale, self._rows, changed_blocks, in_place=consume_base
            )
        else:
            data = scale_blocks(K.data, self._scale.reshape(-1, 3), self._rows, K.indices)
        self.K_scaled = sp.bsr_matrix((data, K.indices, K.indptr), shape=K.shape)
        self._krylov = krylov or KrylovSolver(
            "elasticity",
            rtol=rtol,
            maxiter=maxiter,
            amg_options=DEFAULT_AMG_OPTIONS if amg_options is None else amg_options,
        )
        self._krylov.defer_near_nullspace(
            partial(scaled_near_nullspace, self._rigid_modes, self._scale, self.constrained)
        )
        self._krylov.set_operator(self.K_scaled, changed=rescaled, scale=self._scale)
        self.consumed = False
        if base is not None and self.updated and consume_base:
            base.consumed = True  # its K and scaled K are now this solver's
        self.assembly_s = time.perf_counter() - t0

    def updatable_to(self, other: MechanicsSolver) -> bool:
        """Whether ``other`` may take this solver's stiffness and update it (same mesh,
        assembler, nu and constraints, all held at zero)."""
        return (
            not self.consumed
            and other.mesh is self.mesh
            and other.assembler is self.assembler
            and other.poisson_ratio == self.poisson_ratio
            and self._lift is None
            and not np.any(other.constraints.values)
            and np.array_equal(other.constraints.dofs, self.constraints.dofs)
        )

    def updated_stiffness(
        self, youngs_modulus_pa: np.ndarray, *, in_place: bool = False
    ) -> tuple[sp.bsr_matrix, np.ndarray] | None:
        """This constrained K with the blocks of the tets whose E (n_tets,) Pa changed assembled
        again, and those blocks' indices (None when more than ``MAX_UPDATED_TETS`` of the tets
        changed, or no plan); ``in_place`` changes this solver's K (38 MB not copied on the
        default grid), which then belongs to the caller."""
        changed = np.flatnonzero(youngs_modulus_pa != self.youngs_modulus_pa)
        if changed.size > MAX_UPDATED_TETS * youngs_modulus_pa.size:
            return None
        K = self.K if in_place else self.K.copy()
        if changed.size == 0:
            return K, np.zeros(0, dtype=np.int64)
        blocks = np.unique(self.assembler.pattern.slot[changed])
        data = self.assembler.stiffness_blocks(youngs_modulus_pa, self.poisson_ratio, blocks)
        if data is None:
            return None
        cm = self.constrained.reshape(-1, 3)
        K.data[blocks] = constrain_blocks(data, self._rows[blocks], K.indices[blocks], cm)
        return K, blocks

    def updated_diagonal(self, K: sp.bsr_matrix, blocks: np.ndarray) -> np.ndarray:
        """diag(K) (3 n_nodes,) for K, this solver's K with ``blocks`` changed: this solver's
        diagonal with those of the changed blocks on the block diagonal read again."""
        diag = self._diag.copy()
        on = blocks[self._rows[blocks] == K.indices[blocks]]
        idx = np.arange(3)
        diag.reshape(-1, 3)[self._rows[on]] = K.data[on][:, idx, idx]
        return diag

    def scaled_data(
        self,
        K: sp.bsr_matrix,
        scale: np.ndarray,
        rows: np.ndarray,
        blocks: np.ndarray,
        *,
        in_place: bool = False,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The 3x3 blocks of D^-1/2 K D^-1/2 for K, this solver's K with ``blocks`` changed, and
        its scale (3 n_nodes,): this solver's scaled blocks with those and every block in a row
        or column whose scale changed scaled again, bit for bit ``scale_blocks`` of all; and the
        indices of the blocks scaled again."""
        moved = np.any(scale.reshape(-1, 3) != self._scale.reshape(-1, 3), axis=1)
        redo = moved[rows] | moved[K.indices]
        redo[blocks] = True
        idx = np.flatnonzero(redo)
        data = self.K_scaled.data if in_place else self.K_scaled.data.copy()
        if in_place:
            self._krylov.before_write(data, idx)
        data[idx] = scale_blocks(K.data[idx], scale.reshape(-1, 3), rows[idx], K.indices[idx])
        return data, idx

    @property
    def krylov(self) -> KrylovSolver:
        """The CG solver of the Jacobi-scaled system D^-1/2 K D^-1/2 (its ``A``, near-nullspace)."""
        return self._krylov

    @property
    def scale(self) -> np.ndarray:
        """D^-1/2 (3 n_nodes,): u = scale * y for the scaled system's solution y."""
        return self._scale

    def load(self, pressure_pa: np.ndarray, p0_pa: float) -> np.ndarray:
        """Right-hand side (3 n_nodes,) of nodal pressure (n_nodes,) in Pa, constraints applied."""
        geom = self.assembler.geom
        dp = np.asarray(pressure_pa, dtype=float) - p0_pa
        f = eigenstress_load(
            geom,
            self.mesh.tets,
            self.mesh.n_nodes,
            dp,
            self.load_weight,
            touching=self.mesh.tets_touching(np.flatnonzero(dp)),
        ).ravel()
        if self._lift is not None:
            f -= self._lift
        f[self.constraints.dofs] = self._constrained_rhs
        return f

    def solve(
        self, pressure_pa: np.ndarray, p0_pa: float = 101325.0, x0: np.ndarray | None = None
    ) -> MechanicsResult:
        """Displacement (n_nodes, 3) in m under nodal pore pressure (n_nodes,) in Pa.

        Warm-starts from ``x0`` (n_nodes, 3) or else the previous solution; raises
        ``SolverDivergedError`` when CG does not reach ``rtol``.
        """
        if self.consumed:
            raise RuntimeError("this solver's operator was handed to the next topology's solver")
        pressure_pa = np.asarray(pressure_pa, dtype=float)
        if pressure_pa.shape != (self.mesh.n_nodes,):
            raise ValueError(f"pressure must have shape ({self.mesh.n_nodes},)")
        t0 = time.perf_counter()
        f = self.load(pressure_pa, p0_pa)
        load_s = time.perf_counter() - t0
        y0 = None if x0 is None else np.asarray(x0, float).ravel() / self._scale
        y, st = self._krylov.solve(f * self._scale, y0)
        u = y * self._scale
        stats = MechanicsStats(
            st.iterations, st.residual, load_s, st.setup_s, st.solve_s, st.rebuilt, st.stale
        )
        return MechanicsResult(u.reshape(-1, 3), stats)


def mechanics_assembler(mesh: TetMesh) -> ElasticAssembler:
    """The elasticity assembler of a Kuhn mesh (pattern, geometry and the gather plan)."""
    geom: ElementGeometry = structured_geometry(mesh.points, mesh.tets, mesh.shape_id)
    return elastic_assembler(build_pattern(mesh.tets, mesh.n_nodes), geom, mesh.shape_id)
