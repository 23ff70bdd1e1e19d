"""One time step of the heat equation, Crank-Nicolson kept monotone (PHYSICS.md section 2).

rho c dT/dt = div(k grad T) + q + s, with -k dT/dn = h (T - T_amb) on the outer faces (h per
side; Robin and mass lumped to the nodes). Written on the mesh edges (``fem.edges``), the
lumped semi-discrete system per node i is

    m_i dT_i/dt = - sum_j w_ij (T_i - T_j) - R_i (T_i - T_amb) + f_i

with m_i = (rho c)_i |V_i|, w_ij >= 0 the edge weights of k (the Kuhn stiffness is an
M-matrix), R_i the lumped h |F|, f_i the nodal Joule load plus the extra source.

Time stepping: a theta rule with theta_i = max(1/2, 1 - m_i / (dt D_i)), D_i = sum_j w_ij + R_i
(the diagonal of K + R). Where dt is small theta_i = 1/2, the midpoint (Crank-Nicolson) rule;
where the explicit half would take a negative coefficient (dt > 2 m_i / D_i) theta_i grows
towards backward Euler just enough to keep it non-negative. Each edge flux uses
theta_ij = max(theta_i, theta_j) and each node's Robin term theta_i, so

    (M/dt + K_theta + theta R) T' = (M/dt - K_(1-theta) - (1-theta) R) T + R T_amb + f

where K_theta is the Laplacian with edge weights theta_ij w_ij. Then
- the implicit matrix is a symmetric M-matrix (SPD): CG applies;
- every explicit coefficient is >= 0 and the rows balance, so without sources T' stays within
  [min(T, T_amb), max(T, T_amb)] (discrete maximum principle) at any dt;
- the edge fluxes cancel in the sum over nodes, so energy is conserved exactly:
  sum m (T' - T) = dt (sum f - sum R (theta T' + (1-theta) T - T_amb)) up to the solver residual.
(The row-wise alternative, node-wise theta in every flux of row i and the row divided by
theta_i, has the symmetric matrix diag(m/(dt theta)) + K + R and is monotone too, but its fluxes
theta_i w_ij (T_i - T_j) no longer cancel pairwise: it leaks energy wherever theta varies.)

Solves run on the unit-diagonal scaling D^-1/2 A D^-1/2 (rtol is its relative residual; plain
CG on it is Jacobi-PCG on A). At small dt the matrix is nearly diagonal and Jacobi-PCG needs a
handful of iterations with no setup; at large dt AMG wins. The choice is made per operator from its
diagonal dominance r = max_i sum_j |A_ij| / A_ii (Gershgorin: cond(D^-1 A) <= (1+r)/(1-r)),
which bounds Jacobi-PCG's iterations; past 250 (measured crossover at 64x64x128, dt ~ 1e3 s:
a Jacobi iteration costs ~1/8 of an AMG one, AMG needs ~18 and a setup) AMG takes over.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp

from diathermy.errors import SceneError
from diathermy.fem.edges import EdgeStiffness, LaplacianPattern, laplacian_pattern
from diathermy.fem.geometry import ElementGeometry
from diathermy.fem.multigrid import SCALAR_AMG_OPTIONS, scaled_candidates, unit_diagonal
from diathermy.fem.scalar import surface_load, volume_load
from diathermy.fem.solvers import KrylovSolver, SolveStats
from diathermy.mesh import SIDES, TetMesh

HeatPreconditioner = Literal["auto", "jacobi", "amg"]


@dataclass(frozen=True)
class HeatMesh:
    """Mesh-level data of the heat equation, built once per mesh.

    Attributes:
        stiffness: edge couplings of the P1 diffusion.
        pattern: CSR pattern of the Laplacian on all nodes.
        tets: (n_tets, 4); geom: element geometry; nodal_volume (n_nodes,) in m^3 (lumped).
        face_area: per side, the lumped boundary area of each node (n_nodes,) in m^2.
    """

    stiffness: EdgeStiffness
    pattern: LaplacianPattern
    tets: np.ndarray
    geom: ElementGeometry
    nodal_volume: np.ndarray
    face_area: dict[str, np.ndarray]

    @property
    def n_nodes(self) -> int:
        return self.stiffness.n_nodes

    def robin(self, h_w_per_m2_k: float | Mapping[str, float]) -> np.ndarray:
        """Lumped Robin coefficients R_i = sum_sides h_side A_side,i (n_nodes,) in W/K."""
        if isinstance(h_w_per_m2_k, Mapping):
            unknown = set(h_w_per_m2_k) - set(SIDES)
            if unknown:
                raise SceneError(f"convective h given for unknown sides {sorted(unknown)}")
            h = {s: float(h_w_per_m2_k.get(s, 0.0)) for s in SIDES}
        else:
            h = dict.fromkeys(SIDES, float(h_w_per_m2_k))
        if any(not v >= 0 for v in h.values()):
            raise SceneError(f"convective h must be >= 0 on every side, got {h}")
        return sum((h[s] * self.face_area[s] for s in SIDES), np.zeros(self.n_nodes))

    def joule_load(self, q: np.ndarray) -> np.ndarray:
        """Nodal load (n_nodes,) in W of a per-tet source q (n_tets,) in W/m^3."""
        return volume_load(self.geom, self.tets, self.n_nodes, q)


def heat_mesh(mesh: TetMesh, geom: ElementGeometry, stiffness: EdgeStiffness) -> HeatMesh:
    """Collect what every heat step of ``mesh`` needs."""
    n = mesh.n_nodes
    face_area = {s: surface_load(mesh.points, mesh.boundary_faces[s], n, 1.0) for s in SIDES}
    return HeatMesh(
        stiffness=stiffness,
        pattern=laplacian_pattern(stiffness),
        tets=mesh.tets,
        geom=geom,
        nodal_volume=volume_load(geom, mesh.tets, n, np.ones(mesh.n_tets)),
        face_area=face_area,
    )


@dataclass(frozen=True)
class HeatOperator:
    """The implicit system of one step size and one set of coefficients.

    Attributes:
        dt_s: step in s. mass: m_i (n_nodes,) in J/K. robin: R_i (n_nodes,) in W/K.
        w: edge weights of k (n_edges,) in W/K. theta: node-wise theta (n_nodes,).
        theta_edge: per-edge theta (n_edges,). matrix: M/dt + K_theta + theta R, CSR.
        scaled, scale: D^-1/2 matrix D^-1/2 and d = diag^-1/2 (n_nodes,), what the solvers see.
        dominance: max_i sum_{j != i} |A_ij| / A_ii of the matrix.
    """

    dt_s: float
    mass: np.ndarray
    robin: np.ndarray
    w: np.ndarray
    theta: np.ndarray
    theta_edge: np.ndarray
    matrix: sp.csr_matrix
    scaled: sp.csr_matrix
    scale: np.ndarray
    dominance: float

    @property
    def fallback_nodes(self) -> np.ndarray:
        """Nodes (sorted indices) where theta > 1/2, i.e. plain CN would not be monotone."""
        return np.flatnonzero(self.theta > 0.5)


def assemble_heat_operator(
    hmesh: HeatMesh,
    dt_s: float,
    rho_c: np.ndarray | float,
    k: np.ndarray | float,
    robin: np.ndarray,
    *,
    monotone: bool = True,
    k_weights: np.ndarray | None = None,
) -> HeatOperator:
    """Build the step's matrix: rho_c (n_nodes,) in J/(m^3 K), k (n_tets,) in W/(m K).

    k_weights: the edge weights of this k (n_edges,) where the caller kept them from before.
    """
    if not dt_s > 0 or not np.isfinite(dt_s):
        raise SceneError(f"time step must be positive and finite, got {dt_s}")
    rc = np.broadcast_to(np.asarray(rho_c, dtype=float), (hmesh.n_nodes,))
    if not np.all(rc > 0) or not np.all(np.isfinite(rc)):
        raise SceneError("volumetric heat capacity rho*c must be positive and finite at every node")
    kk = np.asarray(k, dtype=float)
    if not np.all(kk > 0) or not np.all(np.isfinite(kk)):
        raise SceneError("thermal conductivity must be positive and finite in every tet")
    stiff = hmesh.stiffness
    mass = rc * hmesh.nodal_volume
    w = stiff.weights(kk) if k_weights is None else k_weights
    theta = np.full(hmesh.n_nodes, 0.5)
    if monotone:
        diag = stiff.degree(w) + robin
        with np.errstate(divide="ignore"):
            theta = np.maximum(0.5, 1.0 - mass / (dt_s * diag))
    theta_edge = np.maximum(theta[stiff.edges[:, 0]], theta[stiff.edges[:, 1]])
    wt = theta_edge * w
    A = hmesh.pattern.matrix(stiff, wt, mass / dt_s + theta * robin)
    off = stiff.degree(np.abs(wt))
    scaled, scale = unit_diagonal(A)
    return HeatOperator(
        dt_s=float(dt_s),
        mass=mass,
        robin=robin,
        w=w,
        theta=theta,
        theta_edge=theta_edge,
        matrix=A,
        scaled=scaled,
        scale=scale,
        dominance=float(np.max(off / A.diagonal())),
    )


def heat_rhs(
    op: HeatOperator, stiff: EdgeStiffness, T: np.ndarray, t_amb_k: float, load: np.ndarray
) -> np.ndarray:
    """Right-hand side (n_nodes,) in W: explicit half of the step plus Robin and nodal loads."""
    explicit = stiff.apply((1.0 - op.theta_edge) * op.w, T)
    return (
        op.mass / op.dt_s * T
        - explicit
        - (1.0 - op.theta) * op.robin * T
        + op.robin * t_amb_k
        + load
    )


@dataclass(frozen=True)
class HeatEnergy:
    """Energy terms of one step in J: sources in, convective loss out, stored in the tissue."""

    joule_j: float
    extra_j: float
    convective_loss_j: float
    stored_j: float

    @property
    def imbalance_j(self) -> float:
        """stored - (joule + extra - loss): zero up to the solver residual."""
        return self.stored_j - (self.joule_j + self.extra_j - self.convective_loss_j)


def heat_energy(
    op: HeatOperator,
    T_old: np.ndarray,
    T_new: np.ndarray,
    t_amb_k: float,
    joule_load: np.ndarray | None,
    extra_load: np.ndarray | None,
) -> HeatEnergy:
    """The energy terms of a step from T_old to T_new (both (n_nodes,) in K)."""
    dt = op.dt_s
    surface_t = op.theta * T_new + (1.0 - op.theta) * T_old - t_amb_k
    return HeatEnergy(
        joule_j=dt * float(joule_load.sum()) if joule_load is not None else 0.0,
        extra_j=dt * float(extra_load.sum()) if extra_load is not None else 0.0,
        convective_loss_j=dt * float(np.dot(op.robin, surface_t)),
        stored_j=float(np.dot(op.mass, T_new - T_old)),
    )


@dataclass(frozen=True)
class HeatStepStats:
    """One heat step: solver work, preconditioner used, and where theta left 1/2."""

    iterations: int
    residual: float
    preconditioner: str
    assembly_s: float
    setup_s: float
    solve_s: float
    dominance: float
    fallback_nodes: np.ndarray
    theta_max: float


@dataclass(frozen=True)
class HeatStepResult:
    """New temperature T (n_nodes,) in K, the step's stats and its energy terms."""

    T: np.ndarray
    stats: HeatStepStats
    energy: HeatEnergy


def jacobi_iterations_bound(dominance: float, rtol: float) -> float:
    """Upper estimate of Jacobi-PCG iterations from r: 1/2 sqrt(kappa) ln(2/rtol)."""
    if dominance >= 1.0:
        return float("inf")
    kappa = (1.0 + dominance) / (1.0 - dominance)
    return 0.5 * np.sqrt(kappa) * np.log(2.0 / rtol)


class HeatStepper:
    """Steps the heat equation, reusing the operator and the solvers while nothing changed.

    Args:
        hmesh: ``heat_mesh(mesh, geom, stiffness)``.
        h_w_per_m2_k: convective coefficient, one for all sides or per side ({"z+": 25.0, ...};
            sides not named are insulated).
        t_ambient_k: ambient temperature in K.
        rtol: relative residual of each solve.
        monotone: False gives plain Crank-Nicolson (theta = 1/2 everywhere).
        preconditioner: "auto" picks Jacobi while its iteration bound stays <= jacobi_max_iterations.
        amg_stale_factor: keep an AMG hierarchy of an older operator while it needs at most this
            many times the iterations of a fresh one (0: always rebuild, which makes a restarted
            run repeat the original bit for bit).
    """

    def __init__(
        self,
        hmesh: HeatMesh,
        *,
        h_w_per_m2_k: float | Mapping[str, float] = 25.0,
        t_ambient_k: float = 298.15,
        rtol: float = 1e-10,
        monotone: bool = True,
        preconditioner: HeatPreconditioner = "auto",
        jacobi_max_iterations: float = 250.0,
        amg_stale_factor: float = 1.5,
    ) -> None:
        self.hmesh = hmesh
        self.robin = hmesh.robin(h_w_per_m2_k)
        self.t_ambient_k = float(t_ambient_k)
        self.monotone = monotone
        self.preconditioner = preconditioner
        self.jacobi_max_iterations = jacobi_max_iterations
        self.rtol = rtol
        self._solvers = {  # on the unit-diagonal matrix, where Jacobi is the identity
            "jacobi": KrylovSolver("heat", rtol=rtol, preconditioner="none"),
            "amg": KrylovSolver(
                "heat", rtol=rtol, amg_options=SCALAR_AMG_OPTIONS, stale_factor=amg_stale_factor
            ),
        }
        self._key: tuple[float, np.ndarray, np.ndarray] | None = None
        self._op: HeatOperator | None = None
        self._fresh: set[str] = set()

    def operator(
        self, dt_s: float, rho_c: np.ndarray | float, k: np.ndarray | float
    ) -> tuple[HeatOperator, float]:
        """The step's operator (rebuilt only if dt, rho_c or k changed) and the assembly time."""
        rc = np.broadcast_to(np.asarray(rho_c, dtype=float), (self.hmesh.n_nodes,))
        kk = np.broadcast_to(np.asarray(k, dtype=float), self.hmesh.geom.volumes.shape)
        if self._op is not None and self._key is not None:
            dt0, rc0, k0 = self._key
            same_k = _same(k0, kk)
            if dt0 == dt_s and same_k and _same(rc0, rc):
                return self._op, 0.0
        else:
            same_k = False
        t0 = time.perf_counter()
        self._op = assemble_heat_operator(
            self.hmesh,
            dt_s,
            rc,
            kk,
            self.robin,
            monotone=self.monotone,
            k_weights=self._op.w if same_k and self._op is not None else None,
        )
        self._key = (float(dt_s), rc.copy(), kk.copy())
        self._fresh = set(self._solvers)
        return self._op, time.perf_counter() - t0

    def choose_preconditioner(self, op: HeatOperator) -> str:
        """ "jacobi" or "amg" for this operator (fixed unless ``preconditioner`` is "auto")."""
        if self.preconditioner != "auto":
            return self.preconditioner
        bound = jacobi_iterations_bound(op.dominance, self.rtol)
        return "jacobi" if bound <= self.jacobi_max_iterations else "amg"

    def solve(
        self, op: HeatOperator, b: np.ndarray, x0: np.ndarray
    ) -> tuple[np.ndarray, SolveStats, str]:
        """Solve op.matrix T = b from x0 with the chosen preconditioner (on the scaled system)."""
        name = self.choose_preconditioner(op)
        solver = self._solvers[name]
        if name in self._fresh:
            solver.near_nullspace = scaled_candidates(op.scale)
            solver.set_operator(op.scaled)
            self._fresh.discard(name)
        y, st = solver.solve(op.scale * b, x0 / op.scale)
        return op.scale * y, st, name

    def step(
        self,
        T: np.ndarray,
        dt_s: float,
        *,
        rho_c: np.ndarray | float,
        k: np.ndarray | float,
        q: np.ndarray | None = None,
        source_w: np.ndarray | None = None,
        joule_load_w: np.ndarray | None = None,
    ) -> HeatStepResult:
        """Advance T (n_nodes,) in K by dt_s.

        rho_c: nodal volumetric heat capacity (n_nodes,) in J/(m^3 K); k: conductivity per tet
        (n_tets,) in W/(m K); q: Joule heat per tet (n_tets,) in W/m^3; source_w: extra nodal
        source (n_nodes,) in W (a nodal load, e.g. minus the latent heat rate); joule_load_w:
        the nodal load (n_nodes,) in W of q where the caller already has it (skips summing q).
        """
        op, assembly_s = self.operator(dt_s, rho_c, k)
        joule = joule_load_w
        if joule is None and q is not None:
            joule = self.hmesh.joule_load(q)
        load = np.zeros(self.hmesh.n_nodes)
        for part in (joule, source_w):
            if part is not None:
                load = load + part
        b = heat_rhs(op, self.hmesh.stiffness, T, self.t_ambient_k, load)
        T_new, st, name = self.solve(op, b, T)
        return HeatStepResult(
            T=T_new,
            stats=self.stats(op, st, name, assembly_s),
            energy=heat_energy(op, T, T_new, self.t_ambient_k, joule, source_w),
        )

    @staticmethod
    def stats(op: HeatOperator, st: SolveStats, name: str, assembly_s: float) -> HeatStepStats:
        return HeatStepStats(
            iterations=st.iterations,
            residual=st.residual,
            preconditioner=name,
            assembly_s=assembly_s,
            setup_s=st.setup_s,
            solve_s=st.solve_s,
            dominance=op.dominance,
            fallback_nodes=op.fallback_nodes,
            theta_max=float(op.theta.max()),
        )


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and bool(np.array_equal(a, b))
