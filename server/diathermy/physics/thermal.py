"""One time step of the heat equation, Crank-Nicolson kept monotone (PHYSICS.md section 2): the
solver of ``heat_operator``'s system.

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

from diathermy.fem.edge_update import EdgeIncidence, edge_incidence
from diathermy.fem.multigrid import SCALAR_AMG_OPTIONS, scaled_candidates
from diathermy.fem.solvers import KrylovSolver, SolveStats
from diathermy.physics.heat_operator import (
    HeatEnergy,
    HeatMesh,
    HeatOperator,
    assemble_heat_operator,
    heat_energy,
    heat_rhs,
)
from diathermy.physics.heat_operator_update import updated_heat_operator

HeatPreconditioner = Literal["auto", "jacobi", "amg"]

UPDATE_MAX_CHANGED = 0.05
"""A step whose rho c and k changed on at most this fraction of the nodes or tets updates the
last operator (bit for bit, ``updated_heat_operator``); above it, or with a new dt, the operator
is assembled anew."""


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
        self._incidence: EdgeIncidence | None = None  # built on the first update
        self._op: HeatOperator | None = None
        self._fresh: set[str] = set()

    def operator(
        self, dt_s: float, rho_c: np.ndarray | float, k: np.ndarray | float
    ) -> tuple[HeatOperator, float]:
        """The step's operator (rebuilt only if dt, rho_c or k changed) and the assembly time."""
        rc = np.broadcast_to(np.asarray(rho_c, dtype=float), (self.hmesh.n_nodes,))
        kk = np.broadcast_to(np.asarray(k, dtype=float), self.hmesh.geom.volumes.shape)
        t0 = time.perf_counter()
        previous, kept_w = None, None
        if self._op is not None and self._key is not None:
            dt0, rc0, k0 = self._key
            changed_nodes = np.flatnonzero(rc != rc0)
            changed_tets = np.flatnonzero(kk != k0)
            kept_w = self._op.w if changed_tets.size == 0 else None
            if dt0 == dt_s and changed_nodes.size == 0 and changed_tets.size == 0:
                return self._op, 0.0
            few = UPDATE_MAX_CHANGED * max(rc.size, kk.size)
            if dt0 == dt_s and changed_nodes.size + changed_tets.size <= few:
                previous = self._op
        if previous is not None:
            if self._incidence is None:
                hm = self.hmesh
                self._incidence = edge_incidence(hm.stiffness, kk.size, hm.pattern)
            self._op = updated_heat_operator(
                self.hmesh,
                self._incidence,
                previous,
                rc,
                kk,
                changed_nodes,
                changed_tets,
                monotone=self.monotone,
            )
        else:
            self._op = assemble_heat_operator(
                self.hmesh, dt_s, rc, kk, self.robin, monotone=self.monotone, k_weights=kept_w
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
