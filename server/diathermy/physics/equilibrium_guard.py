"""The equilibrium guard of a surrogate displacement: its FEM residual, and a CG correction.

A surrogate (the CNN) predicts u from (p, phi) without solving anything; the guard measures how
far that u is from equilibrium in the FEM's own terms, the relative residual
||f - K u|| / ||f|| over the free DOFs, and, when it is too large, continues the FEM solve from
u with preconditioned CG until the residual is below the tolerance. The residual is evaluated
with one sparse mat-vec of the assembled stiffness of the current topology (assembled again only
when E changes; ``internal_force`` is the matrix-free twin); only a correction builds the full
``MechanicsSolver`` (constraints, loose fragments, preconditioner).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from diathermy.fem.elastic import eigenstress_load, lame_parameters
from diathermy.fem.geometry import ElementGeometry
from diathermy.fem.solvers import deterministic_sa
from diathermy.physics.mechanics import MechanicsSolver

GuardPreconditioner = Literal["amg", "jacobi"]


def internal_force(
    geom: ElementGeometry, tets: np.ndarray, u: np.ndarray, youngs_modulus_pa: np.ndarray, nu: float
) -> np.ndarray:
    """K u matrix-free: nodal internal force (n_nodes, 3) in N of u (n_nodes, 3) m, E per tet Pa.

    Per tet sigma = lambda tr(eps) I + 2 mu eps is constant, and the force on its node a is
    |T| sigma grad N_a (the P1 stiffness applied to u, without assembling it).
    """
    G = np.einsum("eai,eak->eik", u[tets], geom.grads)
    eps = 0.5 * (G + np.swapaxes(G, 1, 2))
    lam, mu = lame_parameters(youngs_modulus_pa, nu)
    sigma = 2.0 * np.asarray(mu)[..., None, None] * eps
    idx = np.arange(3)
    sigma[:, idx, idx] += (np.asarray(lam) * np.trace(eps, axis1=1, axis2=2))[:, None]
    force = np.einsum("eik,eak->eai", sigma * geom.volumes[:, None, None], geom.grads)
    n_nodes = u.shape[0]
    flat = tets.ravel()
    return np.column_stack(
        [np.bincount(flat, force[:, :, i].ravel(), minlength=n_nodes) for i in range(3)]
    )


def relative_residual(f: np.ndarray, Ku: np.ndarray, free: np.ndarray) -> float:
    """||f - K u|| / ||f|| over the free DOFs: f, K u (n_nodes, 3) N, free bool (n_nodes, 3).

    0 when f = 0 and K u = 0; +inf when only f is 0 (any force where none should be).
    """
    f_norm = float(np.linalg.norm(f[free]))
    r_norm = float(np.linalg.norm((f - Ku)[free]))
    if f_norm == 0.0:
        return 0.0 if r_norm == 0.0 else float("inf")
    return r_norm / f_norm


def ritz_scale(f: np.ndarray, Ku: np.ndarray, u: np.ndarray, free: np.ndarray) -> float:
    """alpha = (u . f) / (u . K u) over the free DOFs: the best multiple of u in the energy norm.

    The FEM solution u* minimises the energy; among alpha u, ||u* - alpha u||_K is smallest at
    this alpha (a Ritz projection on span{u}), so alpha u is never farther from u* than u is.
    Returns 1 when u carries no energy (nothing to scale).
    """
    uKu = float(np.sum((u * Ku)[free]))
    if not uKu > 0.0:
        return 1.0
    return float(np.sum((u * f)[free])) / uKu


def equilibrium_residual(
    geom: ElementGeometry,
    tets: np.ndarray,
    u: np.ndarray,
    pressure_pa: np.ndarray,
    p0_pa: float,
    youngs_modulus_pa: np.ndarray,
    nu: float,
    healthy: np.ndarray,
    free: np.ndarray,
    stiffness: Any = None,
) -> float:
    """||f - K u|| / ||f|| over the free DOFs (bool (n_nodes, 3)) of u (n_nodes, 3) m.

    f is the eigenstress load of the nodal pressure (n_nodes,) Pa carried by healthy tets. K u
    is ``stiffness @ u`` when the assembled stiffness of this E is given (one sparse mat-vec),
    else evaluated matrix-free (``internal_force``).
    """
    f = eigenstress_load(geom, tets, u.shape[0], np.asarray(pressure_pa) - p0_pa, healthy)
    if stiffness is not None:
        Ku = (stiffness @ u.ravel()).reshape(-1, 3)
    else:
        Ku = internal_force(geom, tets, u, youngs_modulus_pa, nu)
    return relative_residual(f, Ku, free)


@dataclass(frozen=True)
class Correction:
    """What a guard correction did: u (n_nodes, 3) m, CG iterations, residuals, time in s."""

    u: np.ndarray
    iterations: int
    residual_before: float
    residual_after: float
    setup_s: float
    solve_s: float


class GuardPreconditioners:
    """The preconditioner of the Jacobi-scaled system of one ``MechanicsSolver``, built lazily.

    "amg": the solver's own smoothed-aggregation hierarchy (setup once per topology);
    "jacobi": none on the scaled system, whose diagonal is already one (no setup).
    """

    def __init__(self, kind: GuardPreconditioner) -> None:
        if kind not in ("amg", "jacobi"):
            raise ValueError(f"guard preconditioner must be 'amg' or 'jacobi', got {kind!r}")
        self.kind = kind
        self._solver: MechanicsSolver | None = None
        self._M: Any = None

    def get(self, solver: MechanicsSolver) -> tuple[Any, float]:
        """(preconditioner or None, setup time in s) for ``solver``'s scaled operator."""
        if self.kind == "jacobi":
            return None, 0.0
        if self._solver is solver and self._M is not None:
            return self._M, 0.0
        t0 = time.perf_counter()
        kry = solver.krylov
        ml = deterministic_sa(kry.A, kry.near_nullspace, kry.amg_options)
        self._solver, self._M = solver, ml.aspreconditioner(cycle="V")
        return self._M, time.perf_counter() - t0


def correct(
    solver: MechanicsSolver,
    u0: np.ndarray,
    pressure_pa: np.ndarray,
    p0_pa: float,
    *,
    tol: float,
    maxiter: int,
    preconditioner: GuardPreconditioners,
) -> Correction:
    """Preconditioned CG on ``solver``'s FEM system started from u0 (n_nodes, 3) m.

    Runs on the Jacobi-scaled system y = u / s (s = diag(K)^-1/2) and stops as soon as the
    *unscaled* free-DOF residual ||f - K u|| / ||f|| is at most ``tol`` (or after ``maxiter``
    iterations: the result then says how far it got; the caller decides what that means).
    """
    t0 = time.perf_counter()
    M, setup_s = preconditioner.get(solver)
    s = solver.scale
    free = ~solver.constrained
    A = solver.krylov.A
    f = solver.load(pressure_pa, p0_pa)
    f_norm = float(np.linalg.norm(f[free]))
    y = np.asarray(u0, float).ravel() / s
    y[~free] = f[~free] * s[~free]  # constrained rows: K_ii u_i = f_i (diag kept, scaled: 1)
    r_s = f * s - A @ y

    def unscaled(r: np.ndarray) -> float:
        return float(np.linalg.norm((r / s)[free])) / f_norm if f_norm > 0 else 0.0

    before = res = unscaled(r_s)
    its = 0
    if res > tol:
        z = r_s if M is None else M @ r_s
        d = z.copy()
        rz = float(r_s @ z)
        while its < maxiter and res > tol and rz > 0:
            q = A @ d
            alpha = rz / float(d @ q)
            y += alpha * d
            r_s -= alpha * q
            its += 1
            res = unscaled(r_s)
            z = r_s if M is None else M @ r_s
            rz_new = float(r_s @ z)
            d = z + (rz_new / rz) * d
            rz = rz_new
        res = unscaled(f * s - A @ y)  # the true residual, not the recurrence's
    u = (y * s).reshape(-1, 3)
    return Correction(u, its, before, res, setup_s, time.perf_counter() - t0 - setup_s)


def jacobi_cg(
    stiffness: Any,
    f: np.ndarray,
    u0: np.ndarray,
    free: np.ndarray,
    *,
    tol: float,
    maxiter: int,
) -> Correction:
    """Jacobi-preconditioned CG on the free DOFs of K u = f, from u0 (n_nodes, 3) m.

    ``stiffness`` is the assembled (unconstrained) K, f the load (n_nodes, 3) N, free bool
    (n_nodes, 3); constrained DOFs stay 0. No setup at all: after a topology change it costs
    only its mat-vecs. Stops once ||f - K u|| / ||f|| on the free DOFs is at most ``tol`` or after
    ``maxiter`` iterations (the result says how far it got).
    """
    t0 = time.perf_counter()
    m = free.ravel()
    inv_diag = np.where(m, 1.0 / np.where(m, stiffness.diagonal(), 1.0), 0.0)
    b = np.where(m, f.ravel(), 0.0)
    b_norm = float(np.linalg.norm(b))
    x = np.where(m, np.asarray(u0, float).ravel(), 0.0)

    def apply(v: np.ndarray) -> np.ndarray:
        return np.where(m, stiffness @ v, 0.0)

    r = b - apply(x)

    def rel(v: np.ndarray) -> float:
        return float(np.linalg.norm(v)) / b_norm if b_norm > 0 else 0.0

    before = res = rel(r)
    its = 0
    if res > tol:
        z = inv_diag * r
        d = z.copy()
        rz = float(r @ z)
        while its < maxiter and res > tol and rz > 0:
            q = apply(d)
            alpha = rz / float(d @ q)
            x += alpha * d
            r -= alpha * q
            its += 1
            res = rel(r)
            z = inv_diag * r
            rz_new = float(r @ z)
            d = z + (rz_new / rz) * d
            rz = rz_new
        res = rel(b - apply(x))  # the true residual, not the recurrence's
    return Correction(x.reshape(-1, 3), its, before, res, 0.0, time.perf_counter() - t0)
