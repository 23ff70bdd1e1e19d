"""Incremental FEM mechanics: the previous displacement as the prediction, checked and corrected.

Between two steps the pore pressure changes on a few hot nodes and a few tets are cut, so the
last displacement is nearly the new one. Each step it is Ritz-scaled (the multiple closest in
the energy norm), corrected by the patch solve where its residual concentrates (the crater
wall, ``patch_correction``), and accepted when the relative equilibrium residual
||f - K u|| / ||f|| of the *new* system (one sparse mat-vec) is at most ``guard_tolerance``;
otherwise, and at least every ``full_every`` solves, CG solves the full system from it to the
FEM tolerance. Each answer says which path it took and why (``extra["mode"]``, ``["why"]``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from diathermy.physics.equilibrium_guard import ritz_scale
from diathermy.physics.mechanics import MechanicsSolver
from diathermy.physics.mechanics_backend import FEMBackend, MechanicsOutput, Rescaled
from diathermy.physics.patch_correction import node_graph, patch_correct, residual_patch

DEFAULT_GUARD_TOLERANCE = 1e-2
"""Relative residual the local path must reach: on the 9x9x17 test block with a cut, max
strain-energy error 0.33 % and max temperature error 0.005 K against full solves (1e-3: mostly
full solves; 3e-2: 0.83 %); the default grids: benchmarks/results/realtime.md."""


@dataclass(frozen=True)
class IncrementalSettings:
    """Knobs of the local path: the residual it must reach, the full-solve interval, the patch."""

    guard_tolerance: float = DEFAULT_GUARD_TOLERANCE
    full_every: int = 10
    patch_threshold: float = 0.1
    patch_layers: int = 2
    patch_max_nodes: int = 4000
    patch_rounds: int = 3

    def __post_init__(self) -> None:
        if not self.guard_tolerance > 0 or self.full_every < 1 or self.patch_rounds < 1:
            raise ValueError("guard_tolerance must be > 0, full_every and patch_rounds >= 1")


@dataclass(frozen=True)
class LocalSolve:
    """The predictor's answer: u (n_nodes, 3) m, its residual, the patch size, the Ritz factor."""

    u: np.ndarray
    residual: float
    residual_before: float
    patch_nodes: np.ndarray  # nodes where u is not ritz_scale x u_prev
    ritz_scale: float


def local_solve(
    solver: MechanicsSolver,
    u_prev: np.ndarray,
    pressure_pa: np.ndarray,
    p0_pa: float,
    graph: sp.csr_matrix,
    settings: IncrementalSettings,
) -> LocalSolve:
    """Ritz-scaled ``u_prev`` (n_nodes, 3) m, patch-corrected on ``solver``'s system for the
    nodal pressure (n_nodes,) Pa; residuals over the free DOFs."""
    free = ~solver.constrained.reshape(-1, 3)
    f = solver.load(pressure_pa, p0_pa).reshape(-1, 3)
    u = np.where(free, u_prev, 0.0)
    Ku = (solver.K @ u.ravel()).reshape(-1, 3)
    alpha = ritz_scale(f, Ku, u, free)
    u, Ku = alpha * u, alpha * Ku
    moved = np.zeros(0, dtype=np.int64)
    first = None
    for _ in range(settings.patch_rounds):  # each round patches where the last one left off
        nodes = residual_patch(
            np.where(free, f - Ku, 0.0),
            graph,
            threshold=settings.patch_threshold,
            layers=settings.patch_layers,
            max_nodes=settings.patch_max_nodes,
        )
        patched = patch_correct(solver.K, f, u, Ku, free, nodes)
        first = patched.residual_before if first is None else first
        u, Ku = patched.u, patched.Ku
        if patched.nodes:
            moved = np.union1d(moved, nodes)
        if patched.residual_after <= settings.guard_tolerance or not patched.nodes:
            break
    held = np.flatnonzero(np.any(~free & (u_prev != 0), axis=1))  # zeroed constrained values
    moved = np.union1d(moved, held)
    assert first is not None
    return LocalSolve(u, patched.residual_after, first, moved, alpha)


class IncrementalFEMBackend:
    """The FEM backend with the previous displacement as predictor (``mechanics.predictor``
    "previous"); the full solve is ``fem``'s, with its kept operator and AMG hierarchy."""

    name = "fem"

    def __init__(self, fem: FEMBackend, settings: IncrementalSettings) -> None:
        self.fem = fem
        self.settings = settings
        self._graph: sp.csr_matrix | None = None
        self.since_full = 0
        self.n_local = 0
        self.n_full = 0
        self._forced: str | None = None
        self.last_E_pa: np.ndarray | None = None  # E per tet of the solve behind the warm start

    def force_full(self, why: str) -> None:
        """Solve the next step in full, saying ``why``."""
        self._forced = why

    def full_reason(self, warm_start: np.ndarray | None) -> str | None:
        """Why this step must solve in full (None: the local path may serve)."""
        if self._forced is not None:
            return f"forced: {self._forced}"
        if warm_start is None or not np.any(warm_start):
            return "no previous displacement to start from"
        if self.since_full + 1 >= self.settings.full_every:
            return f"interval: a full solve every {self.settings.full_every} solves"
        return None

    def solve(
        self,
        *,
        pressure_pa: np.ndarray,
        level_set_m: np.ndarray,
        youngs_modulus_pa: np.ndarray,
        healthy: np.ndarray,
        warm_start: np.ndarray | None,
    ) -> MechanicsOutput:
        t0 = time.perf_counter()
        solver, rebuilt = self.fem.operator_for(youngs_modulus_pa, healthy)
        operator_s = time.perf_counter() - t0
        why = self.full_reason(warm_start)
        extra: dict[str, float | int | bool | str] = {"operator_s": operator_s}
        x0 = warm_start
        if why is None:
            assert warm_start is not None
            if self._graph is None:
                self._graph = node_graph(solver.K)  # the mesh's pattern: built once
            local = local_solve(
                solver, warm_start, pressure_pa, self.fem.p0_pa, self._graph, self.settings
            )
            extra.update(
                residual_before=local.residual_before,
                patch_nodes=int(local.patch_nodes.size),
                ritz_scale=local.ritz_scale,
                local_s=time.perf_counter() - t0 - operator_s,
            )
            tol = self.settings.guard_tolerance
            if local.residual <= tol:
                self.since_full += 1
                self.n_local += 1
                loose = solver.fragments.loose
                previous_E, self.last_E_pa = self.last_E_pa, solver.youngs_modulus_pa
                extra.update(
                    mode="local",
                    why=f"residual {local.residual:.1e} <= {tol:.0e}",
                    guard_tolerance=tol,
                )
                return MechanicsOutput(
                    u=local.u,
                    residual=local.residual,
                    rebuilt=rebuilt,
                    loose_tets=loose if loose.any() else None,
                    rescaled=None
                    if previous_E is None
                    else Rescaled(local.ritz_scale, local.patch_nodes, previous_E),
                    extra=extra,
                )
            why = f"residual {local.residual:.1e} > {tol:.0e} after the patch"
            x0 = local.u
        out = self.fem.solve(
            pressure_pa=pressure_pa,
            level_set_m=level_set_m,
            youngs_modulus_pa=youngs_modulus_pa,
            healthy=healthy,
            warm_start=x0,
        )
        self.since_full = 0
        self.n_full += 1
        self._forced = None
        self.last_E_pa = self.fem.solver.youngs_modulus_pa if self.fem.solver else None
        return MechanicsOutput(
            u=out.u,
            iterations=out.iterations,
            residual=out.residual,
            rebuilt=out.rebuilt or rebuilt,
            loose_tets=out.loose_tets,
            extra={**out.extra, **extra, "mode": "full", "why": why},
        )
