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
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from diathermy.errors import SceneError
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

_CHEBYSHEV = ("chebyshev", {"degree": 3})
DEFAULT_AMG_OPTIONS: dict[str, Any] = {
    "presmoother": _CHEBYSHEV,
    "postsmoother": _CHEBYSHEV,
    "max_coarse": 64,
    "coarse_solver": "pinv",
}
"""Smoothed aggregation for the 3x3-block elasticity matrix (measured in benchmarks/mechanics.py)."""


@dataclass(frozen=True)
class Constraints:
    """Prescribed displacement components: DOF ``3 * node + i`` held at ``values`` (m)."""

    dofs: np.ndarray
    values: np.ndarray

    def __post_init__(self) -> None:
        dofs = np.asarray(self.dofs, dtype=np.int64).ravel()
        values = np.broadcast_to(np.asarray(self.values, dtype=float), dofs.shape)
        if not np.all(np.isfinite(values)):
            raise SceneError("constraint values must be finite")
        dofs, first = np.unique(dofs, return_index=True)  # later duplicates are dropped
        object.__setattr__(self, "dofs", dofs)
        object.__setattr__(self, "values", np.ascontiguousarray(values[first]))

    @classmethod
    def on_nodes(
        cls, nodes: np.ndarray, components: tuple[int, ...] = (0, 1, 2), value_m: float = 0.0
    ) -> Constraints:
        """Hold the given components (0 x, 1 y, 2 z) of ``nodes`` at ``value_m``."""
        comps = np.asarray(components, dtype=np.int64)
        dofs = 3 * np.asarray(nodes, dtype=np.int64)[:, None] + comps[None, :]
        return cls(dofs.ravel(), np.full(dofs.size, value_m))

    def __add__(self, other: Constraints) -> Constraints:
        return Constraints(
            np.concatenate([self.dofs, other.dofs]), np.concatenate([self.values, other.values])
        )

    def mask(self, n_dofs: int) -> np.ndarray:
        """Boolean (n_dofs,) of the constrained DOFs."""
        if self.dofs.size and (self.dofs[0] < 0 or self.dofs[-1] >= n_dofs):
            raise SceneError(f"constrained DOFs must lie in [0, {n_dofs})")
        out = np.zeros(n_dofs, dtype=bool)
        out[self.dofs] = True
        return out


def clamped_bottom(mesh: TetMesh) -> Constraints:
    """u = 0 on the bottom z- (the tissue lies on the dispersive electrode)."""
    return Constraints.on_nodes(mesh.side_nodes("z-"))


def rollers(mesh: TetMesh, sides: tuple[str, ...]) -> Constraints:
    """Zero normal displacement on each named side (``x-``, ``y+``, ...); tangential free."""
    out = Constraints(np.zeros(0, dtype=np.int64), np.zeros(0))
    for side in sides:
        out = out + Constraints.on_nodes(mesh.side_nodes(side), ("xyz".index(side[0]),))
    return out


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


@dataclass(frozen=True)
class Fragments:
    """Face-connected components of the healthy tets and which of them float."""

    labels: np.ndarray  # (n_tets,) component of each healthy tet, -1 elsewhere
    n_components: int
    loose: np.ndarray = field(repr=False)  # (n_tets,) healthy tets of unanchored components


def find_fragments(
    mesh: TetMesh, healthy: np.ndarray, constrained: np.ndarray, *, tol: float = 1e-9
) -> Fragments:
    """Components of the healthy-tet face graph; a component is anchored when the constrained
    DOFs (bool (3 n_nodes,)) on its nodes fix all 6 rigid-body modes (rank-6 Gram matrix)."""
    healthy = np.asarray(healthy, dtype=bool)
    ids = np.flatnonzero(healthy)
    local = np.full(mesh.n_tets, -1, dtype=np.int64)
    local[ids] = np.arange(ids.size)
    nb = mesh.neighbours[ids]
    keep = nb >= 0
    keep[keep] = healthy[nb[keep]]
    rows = np.repeat(np.arange(ids.size), 4).reshape(-1, 4)[keep]
    graph = sp.csr_matrix((np.ones(rows.size), (rows, local[nb[keep]])), (ids.size, ids.size))
    n_comp, comp = connected_components(graph, directed=False)
    labels = np.full(mesh.n_tets, -1, dtype=np.int64)
    labels[ids] = comp
    # (component, node) pairs, then the Gram matrix of the rigid modes at constrained DOFs.
    pairs = np.unique(comp[:, None] * np.int64(mesh.n_nodes) + mesh.tets[ids])
    pc, pn = np.divmod(pairs, mesh.n_nodes)
    B = rigid_body_modes(mesh.points).reshape(mesh.n_nodes, 3, 6)
    cm = constrained.reshape(-1, 3)[pn]  # (n_pairs, 3)
    gram = np.zeros(n_comp * 36)
    for i in range(3):
        sel = cm[:, i]
        Bi = B[pn[sel], i]
        slots = pc[sel][:, None] * 36 + np.arange(36)
        gram += np.bincount(
            slots.ravel(), (Bi[:, :, None] * Bi[:, None, :]).ravel(), minlength=gram.size
        )
    gram = gram.reshape(n_comp, 6, 6)
    smallest = np.linalg.eigvalsh(gram)[:, 0]
    scale = np.trace(gram, axis1=1, axis2=2).max(initial=0.0)
    anchored = smallest > tol * max(scale, 1.0)
    loose = np.zeros(mesh.n_tets, dtype=bool)
    loose[ids] = ~anchored[comp]
    return Fragments(labels, n_comp, loose)


def _constrain(K: sp.bsr_matrix, constrained: np.ndarray) -> np.ndarray:
    """Zero the rows and columns of constrained DOFs in place, keep their diagonal; returns it."""
    diag = K.diagonal()
    n_blocks = K.indptr.size - 1
    rows = np.repeat(np.arange(n_blocks), np.diff(K.indptr))
    cm = constrained.reshape(-1, 3)
    K.data *= ~(cm[rows][:, :, None] | cm[K.indices][:, None, :])
    on_diag = np.flatnonzero(rows == K.indices)
    blocks = K.data[on_diag]  # (n_blocks, 3, 3) view-free copy, written back below
    idx = np.arange(3)
    d = diag.reshape(-1, 3)[rows[on_diag]]
    blocks[:, idx, idx] = np.where(cm[rows[on_diag]], d, blocks[:, idx, idx])
    K.data[on_diag] = blocks
    return diag


class MechanicsSolver:
    """The elastic operator of one topology, solved for many pressure fields.

    Args:
        mesh: the tet mesh.
        youngs_modulus_pa: E per tet (n_tets,) or one number; cut tissue at the ersatz level.
        poisson_ratio: nu in (-1, 0.5); up to 0.49 is tested.
        constraints: prescribed DOFs; default ``clamped_bottom(mesh)``.
        healthy: bool (n_tets,) tissue that carries stiffness and pore pressure; default
            E >= 1e-3 max E (the ersatz level is 1e-6 E).
        ersatz_ratio: modulus of removed (loose) tissue relative to max E.
        loose_fragments: "remove" (default) or "keep"; see the module docstring.
        rtol, maxiter, amg_options: for the AMG-preconditioned CG.
        assembler: a prebuilt ``ElasticAssembler`` of this mesh (saves its setup on re-topology).
        krylov: the CG solver of an earlier topology of this mesh: it takes this operator and
            keeps its hierarchy while that pays (``KrylovSolver.stale_factor``); rtol, maxiter
            and amg_options are then its own.
    """

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
        healthy = np.asarray(healthy, dtype=bool)
        B = rigid_body_modes(mesh.points)
        if np.linalg.matrix_rank(B[self.constrained]) < 6:
            raise SceneError("the constraints leave rigid-body motions of the block free")
        self.fragments = find_fragments(mesh, healthy, self.constrained)
        if loose_fragments == "remove" and self.fragments.loose.any():
            E[self.fragments.loose] = ersatz_ratio * E.max()
            healthy = healthy & ~self.fragments.loose
        elif loose_fragments not in ("remove", "keep"):
            raise ValueError(f"loose_fragments must be 'remove' or 'keep', got {loose_fragments!r}")
        self.youngs_modulus_pa = E
        self.healthy = healthy
        K = self.assembler.stiffness(E, self.poisson_ratio)
        K_values = np.zeros(n_dofs)
        K_values[self.constraints.dofs] = self.constraints.values
        self._lift = K @ K_values if np.any(K_values) else None
        diag = _constrain(K, self.constrained)
        self._constrained_rhs = diag[self.constraints.dofs] * self.constraints.values
        self.K = K
        # Symmetric Jacobi scaling D^-1/2 K D^-1/2: unit diagonal, so the smoother sees the
        # 1e6 stiffness contrast of the ersatz material as well-scaled rows (see benchmarks).
        self._scale = 1.0 / np.sqrt(diag)
        rows = np.repeat(np.arange(mesh.n_nodes), np.diff(K.indptr))
        s3 = self._scale.reshape(-1, 3)
        data = K.data * s3[rows][:, :, None]
        data *= s3[K.indices][:, None, :]  # in place: 2x faster than one expression, same bits
        K_scaled = sp.bsr_matrix((data, K.indices, K.indptr), shape=K.shape)
        B[self.constrained] = 0.0  # near-nullspace restricted to the free DOFs
        B /= self._scale[:, None]
        self._krylov = krylov or KrylovSolver(
            "elasticity",
            rtol=rtol,
            maxiter=maxiter,
            amg_options=DEFAULT_AMG_OPTIONS if amg_options is None else amg_options,
        )
        self._krylov.near_nullspace = B
        self._krylov.set_operator(K_scaled)
        self.assembly_s = time.perf_counter() - t0

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
        f = eigenstress_load(geom, self.mesh.tets, self.mesh.n_nodes, dp, self.healthy).ravel()
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
