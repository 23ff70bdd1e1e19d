"""The coupled electro-thermal step: staggered, or monolithic by block-preconditioned GMRES.

Staggered: potential (re-solved only when sigma or the contact changes), Joule heat
q = sigma |grad V|^2, then the heat step.

Monolithic (the paper's solver): one GMRES solve for [V_free; T] at the new time level,

    [ K_V   0  ] [V]   [load]
    [ -C   A_T ] [T] = [b_T ]

with the Joule coupling linearised about the latest potential V*: q = sigma grad V* . grad V, so
C V is the nodal load of that q and C is sparse (C = P^T S: S (n_tets x n_nodes) holds
sigma |T|/4 grad V* . grad N_b per tet, P the tet-node incidence). Each block row is scaled by
its right-hand side norm; the preconditioner is block lower triangular with one AMG V-cycle on
K_V and one on A_T, or Jacobi on A_T where the heat step would pick it (``thermal_block``).
If V moved away from V* (new sigma or contact, or the first step, which starts from V* = 0),
the step re-linearises about the new V and solves again (Picard), so both methods agree to
solver tolerance. sigma is held fixed within a step, so the V block does not depend on T.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from diathermy.errors import SolverDivergedError
from diathermy.fem.edges import EdgeStiffness, edge_stiffness
from diathermy.fem.geometry import ElementGeometry, gradient
from diathermy.fem.gmres import RightGMRES
from diathermy.fem.multigrid import scaled_amg_preconditioner
from diathermy.mesh import TetMesh
from diathermy.physics.contact_load import ContactWeights
from diathermy.physics.driven_potential import DrivenPotential, ElectrodeDrive, drive_current
from diathermy.physics.electric import PotentialSolver, PotentialStats, joule_heat
from diathermy.physics.heat_operator import HeatEnergy, heat_energy, heat_mesh, heat_rhs
from diathermy.physics.thermal import HeatStepper, HeatStepStats


@dataclass(frozen=True)
class CoupledStepResult:
    """One electro-thermal step.

    Attributes:
        T: temperature (n_nodes,) in K at the new level. V: potential (n_nodes,) in V.
        q: Joule heat per tet (n_tets,) in W/m^3. current_a: injected current in A.
        power_w: int j V over the contact in W. joule_w: sum_e q_e |T_e| in W.
        potential: stats of the potential solve (staggered; None for monolithic).
        heat: stats of the heat solve (monolithic: GMRES iterations, preconditioner "block").
        energy: the heat step's energy terms. wall_s: time of the whole step in s.
        picard_passes: monolithic linearisation passes (staggered: 0).
    """

    T: np.ndarray
    V: np.ndarray
    q: np.ndarray
    current_a: float
    power_w: float
    joule_w: float
    potential: PotentialStats | None
    heat: HeatStepStats
    energy: HeatEnergy
    wall_s: float
    picard_passes: int = 0


class ElectroThermal:
    """Electric potential and heat on one mesh, with the solver state both methods reuse.

    Args:
        mesh, geom: the tet mesh and its element geometry.
        stiffness: its edge couplings (built here if not given).
        potential_rtol, heat_rtol: relative residuals of the two solves.
        h_w_per_m2_k, t_ambient_k, monotone, heat_preconditioner: see ``HeatStepper``.
    """

    def __init__(
        self,
        mesh: TetMesh,
        geom: ElementGeometry,
        *,
        stiffness: EdgeStiffness | None = None,
        potential_rtol: float = 1e-8,
        heat_rtol: float = 1e-10,
        h_w_per_m2_k: float | Mapping[str, float] = 25.0,
        t_ambient_k: float = 298.15,
        monotone: bool = True,
        heat_preconditioner: Literal["auto", "jacobi", "amg"] = "auto",
        potential: DrivenPotential | None = None,
        heat: HeatStepper | None = None,
    ) -> None:
        stiffness = stiffness or edge_stiffness(geom, mesh.tets, mesh.n_nodes)
        self.mesh, self.geom = mesh, geom
        self.potential = potential or DrivenPotential(
            PotentialSolver(mesh, stiffness, rtol=potential_rtol)
        )
        self.heat = heat or HeatStepper(
            heat_mesh(mesh, geom, stiffness),
            h_w_per_m2_k=h_w_per_m2_k,
            t_ambient_k=t_ambient_k,
            rtol=heat_rtol,
            monotone=monotone,
            preconditioner=heat_preconditioner,
        )
        self._gmres = RightGMRES("electro-thermal block system")
        self._block_amg: dict[str, tuple[object, spla.LinearOperator]] = {}
        self._last: tuple[np.ndarray, float] | None = None  # latest (V, I)
        self._unit_joule: tuple[np.ndarray, ...] | None = None  # V1 with its q and load at 1 A

    def staggered_step(
        self,
        T: np.ndarray,
        dt_s: float,
        *,
        sigma: np.ndarray | float,
        contact: ContactWeights,
        drive: ElectrodeDrive,
        rho_c: np.ndarray | float,
        k: np.ndarray | float,
        source_w: np.ndarray | None = None,
    ) -> CoupledStepResult:
        """Potential (cached while sigma and contact stay), Joule heat, then the heat step."""
        t0 = time.perf_counter()
        sig = np.broadcast_to(np.asarray(sigma, dtype=float), (self.mesh.n_tets,))
        V1, load1, R, pot_stats = self.potential.unit_field(sig, contact)
        current = drive_current(drive, contact.area_m2, R)
        if self._unit_joule is None or self._unit_joule[0] is not V1:  # q, load scale with I^2
            q1 = joule_heat(self.mesh.grid, sig, V1)
            self._unit_joule = (V1, q1, self.heat.hmesh.joule_load(q1))
        _, q1, joule1 = self._unit_joule
        q, V = current**2 * q1, current * V1
        heat = self.heat.step(
            T, dt_s, rho_c=rho_c, k=k, q=q, source_w=source_w, joule_load_w=current**2 * joule1
        )
        self._last = (V, current)
        return CoupledStepResult(
            T=heat.T,
            V=V,
            q=q,
            current_a=current,
            power_w=current**2 * R,
            joule_w=float(np.dot(q, self.geom.volumes)),
            potential=pot_stats,
            heat=heat.stats,
            energy=heat.energy,
            wall_s=time.perf_counter() - t0,
        )

    def monolithic_step(
        self,
        T: np.ndarray,
        dt_s: float,
        *,
        sigma: np.ndarray | float,
        contact: ContactWeights,
        drive: ElectrodeDrive,
        rho_c: np.ndarray | float,
        k: np.ndarray | float,
        source_w: np.ndarray | None = None,
        rtol: float = 1e-10,
        thermal_block: Literal["auto", "amg", "jacobi"] = "auto",
        max_picard: int = 3,
    ) -> CoupledStepResult:
        """Solve [V; T] together by GMRES with a block lower-triangular AMG preconditioner."""
        t0 = time.perf_counter()
        sig = np.broadcast_to(np.asarray(sigma, dtype=float), (self.mesh.n_tets,))
        solver = self.potential.solver
        solver.set_conductivity(sig)
        if self._last is None:  # nothing to linearise about yet: the first pass finds V
            self._last = (np.zeros(self.mesh.n_nodes), 0.0)
        op, assembly_s = self.heat.operator(dt_s, rho_c, k)
        load_T = np.zeros(self.mesh.n_nodes) if source_w is None else np.asarray(source_w, float)
        b_T = heat_rhs(op, self.heat.hmesh.stiffness, T, self.heat.t_ambient_k, load_T)
        free, n_f = solver.free, solver.free.size
        K_V = solver.matrix
        assert K_V is not None
        M_V = self._amg("potential", K_V)
        if thermal_block == "auto":
            thermal_block = "jacobi" if self.heat.choose_preconditioner(op) == "jacobi" else "amg"
        M_T = self._thermal_preconditioner(op.matrix, thermal_block)
        V_star, I_star = self._last
        x0 = np.concatenate([V_star[free], T])
        total_its, passes = 0, 0
        while True:
            passes += 1
            current = self._current(V_star, I_star, contact, drive)
            b_V = current * contact.weights[free] / contact.area_m2
            C = self._coupling(sig, V_star)
            x, its, res = _block_gmres(self._gmres, K_V, C, op.matrix, M_V, M_T, b_V, b_T, x0, rtol)
            total_its += its
            V = np.zeros(self.mesh.n_nodes)
            V[free] = x[:n_f]
            change = np.linalg.norm(V - V_star) / max(float(np.linalg.norm(V)), 1e-300)
            if change <= 100 * rtol or passes >= max_picard or current == 0.0:
                break
            # V is exact for this sigma and contact (its block ignores T): rescale it to the
            # drive and re-linearise about it
            I_star = self._current(V, current, contact, drive)
            V_star = V * (I_star / current)
            x0 = np.concatenate([V_star[free], x[n_f:]])
        T_new = x[n_f:]
        q = joule_heat(self.mesh.grid, sig, V)
        joule = self.heat.hmesh.joule_load(q)
        self._last = (V, current)
        heat_stats = HeatStepStats(
            iterations=total_its,
            residual=res,
            preconditioner=f"block-{thermal_block}",
            assembly_s=assembly_s,
            setup_s=0.0,
            solve_s=time.perf_counter() - t0,
            dominance=op.dominance,
            fallback_nodes=op.fallback_nodes,
            theta_max=float(op.theta.max()),
        )
        return CoupledStepResult(
            T=T_new,
            V=V,
            q=q,
            current_a=current,
            power_w=float(np.dot(b_V, V[free])),
            joule_w=float(np.dot(q, self.geom.volumes)),
            potential=None,
            heat=heat_stats,
            energy=heat_energy(op, T, T_new, self.heat.t_ambient_k, joule, source_w),
            wall_s=time.perf_counter() - t0,
            picard_passes=passes,
        )

    def _current(
        self,
        V_star: np.ndarray,
        I_star: float,
        contact: ContactWeights,
        drive: ElectrodeDrive,
    ) -> float:
        """Injected current; constant power takes R = (w . V*) / I* from the linearisation point."""
        if drive.mode == "current_density" and drive.max_voltage_v is None:
            return drive_current(drive, contact.area_m2, 1.0)
        if I_star <= 0:  # no field to read R from: a 1 A pass, rescaled by the next pass
            return 1.0
        R = float(np.dot(contact.weights, V_star)) / (contact.area_m2 * I_star)
        return drive_current(drive, contact.area_m2, R)

    @functools.cached_property
    def _incidence_t(self) -> sp.csr_matrix:
        """(n_nodes, n_tets) 0/1 matrix summing per-tet values onto their vertices."""
        tets, n_t = self.mesh.tets, self.mesh.n_tets
        P = sp.csr_matrix(
            (np.ones(tets.size), tets.ravel(), 4 * np.arange(n_t + 1)),
            shape=(n_t, self.mesh.n_nodes),
        )
        return P.T.tocsr()

    def _coupling(self, sigma: np.ndarray, V_star: np.ndarray) -> spla.LinearOperator:
        """C: free-node V (n_free,) -> nodal load (n_nodes,) of sigma grad V* . grad V."""
        tets, grads = self.mesh.tets, self.geom.grads
        g_star = gradient(self.geom, tets, V_star)
        coeff = sigma * self.geom.volumes / 4.0
        data = coeff[:, None] * np.einsum("ek,eak->ea", g_star, grads)  # (n_tets, 4)
        n_t, n = self.mesh.n_tets, self.mesh.n_nodes
        S = sp.csr_matrix((data.ravel(), tets.ravel(), 4 * np.arange(n_t + 1)), shape=(n_t, n))
        free = self.potential.solver.free
        PT = self._incidence_t
        buf = np.zeros(n)

        def matvec(v: np.ndarray) -> np.ndarray:
            buf[free] = v
            return PT @ (S @ buf)

        return spla.LinearOperator((n, free.size), matvec=matvec, dtype=float)

    def _amg(self, name: str, A: sp.csr_matrix) -> spla.LinearOperator:
        """One scaled AMG V-cycle as a preconditioner, kept while A is the same object."""
        cached = self._block_amg.get(name)
        if cached is None or cached[0] is not A:
            cached = (A, scaled_amg_preconditioner(A))
            self._block_amg[name] = cached
        return cached[1]

    def _thermal_preconditioner(self, A: sp.csr_matrix, kind: str) -> spla.LinearOperator:
        if kind == "amg":
            return self._amg("heat", A)
        inv = 1.0 / A.diagonal()
        return spla.LinearOperator(A.shape, matvec=lambda r: inv * r, dtype=float)


def _block_gmres(
    gmres: RightGMRES,
    K_V: sp.csr_matrix,
    C: spla.LinearOperator,
    A_T: sp.csr_matrix,
    M_V: spla.LinearOperator,
    M_T: spla.LinearOperator,
    b_V: np.ndarray,
    b_T: np.ndarray,
    x0: np.ndarray,
    rtol: float,
) -> tuple[np.ndarray, int, float]:
    """GMRES on the row-scaled 2x2 system; returns x, iterations, max block relative residual."""
    n_f = b_V.size
    s_V = 1.0 / max(float(np.linalg.norm(b_V)), 1e-300)
    s_T = 1.0 / max(float(np.linalg.norm(b_T)), 1e-300)

    def apply(x: np.ndarray) -> np.ndarray:
        v, t = x[:n_f], x[n_f:]
        return np.concatenate([s_V * (K_V @ v), s_T * (A_T @ t - C @ v)])

    def precondition(r: np.ndarray) -> np.ndarray:
        z_V = M_V @ (r[:n_f] / s_V)
        z_T = M_T @ (r[n_f:] / s_T + C @ z_V)
        return np.concatenate([z_V, z_T])

    b = np.concatenate([s_V * b_V, s_T * b_T])  # each block of unit norm
    x, its, _ = gmres.solve(apply, precondition, b, x0, rtol / np.sqrt(2.0))
    r = b - apply(x)
    res = max(float(np.linalg.norm(r[:n_f])), float(np.linalg.norm(r[n_f:])))
    if res > rtol:
        raise SolverDivergedError(
            f"electro-thermal block GMRES: block residual {res:.3e} > {rtol:.1e}",
            iterations=its,
            residual=res,
        )
    return x, its, res
