"""How good and how dear each mechanics predictor is on one step: alone (Ritz-scaled) and with the
patch correction, against the FEM answer's strain energy. Shared by the benchmarks
(hybrid.py, predictors.py) and ``diathermy evaluate`` so that every surrogate figure stands
beside persistence's, measured the same way.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from diathermy.physics.mechanics import MechanicsSolver
from diathermy.physics.patch_correction import node_graph, patch_correct, residual_patch
from diathermy.physics.predictors import Start, ritz_start
from diathermy.physics.strain_energy import relative_strain_energy_error


@dataclass(frozen=True)
class Score:
    """One predictor on one step: relative strain-energy error, seconds (prediction, Ritz scale
    and patch; the operator is shared by all), relative residual, patch nodes."""

    name: str  # e.g. "previous", "previous+patch", "cnn", "cnn+patch"
    error: float
    cost_s: float
    residual: float
    patch_nodes: int = 0


@dataclass(frozen=True)
class StepSystem:
    """The step's system: the solver (its K), load f and free DOFs (n_nodes, 3), node graph."""

    solver: MechanicsSolver
    f: np.ndarray
    free: np.ndarray
    graph: sp.csr_matrix

    @staticmethod
    def of(
        solver: MechanicsSolver,
        pressure_pa: np.ndarray,
        p0_pa: float,
        graph: sp.csr_matrix | None = None,
    ) -> StepSystem:
        """The system of ``solver`` under nodal pressure (n_nodes,) Pa."""
        f = solver.load(pressure_pa, p0_pa).reshape(-1, 3)
        free = ~solver.constrained.reshape(-1, 3)
        return StepSystem(solver, f, free, node_graph(solver.K) if graph is None else graph)

    def matvec(self, u: np.ndarray) -> np.ndarray:
        """K u (n_nodes, 3) N of u (n_nodes, 3) m."""
        return (self.solver.K @ u.ravel()).reshape(-1, 3)

    def start(self, name: str, u0: np.ndarray, predict_s: float = 0.0) -> Start:
        """``u0`` Ritz-scaled on this system (``predictors.ritz_start``)."""
        return ritz_start(name, u0, self.matvec, self.f, self.free, predict_s)

    def patched(
        self, start: Start, *, threshold: float = 0.1, layers: int = 2
    ) -> tuple[np.ndarray, float, int]:
        """(u, relative residual, patch nodes) of ``start`` after the patch correction."""
        nodes = residual_patch(
            np.where(self.free, self.f - start.Ku, 0.0), self.graph,
            threshold=threshold, layers=layers, max_nodes=4000,
        )  # fmt: skip
        p = patch_correct(self.solver.K, self.f, start.u, start.Ku, self.free, nodes)
        return p.u, p.residual_after, p.nodes


def score_start(
    system: StepSystem,
    name: str,
    predict: Callable[[], np.ndarray],
    strain_energy: Callable[[np.ndarray], np.ndarray],
    W_ref: np.ndarray,
    *,
    threshold: float = 0.1,
    layers: int = 2,
) -> tuple[Score, Score]:
    """``name`` alone (its raw u from ``predict``, Ritz-scaled) and ``name+patch``, against the
    reference strain energy ``W_ref`` (n_tets,) J/m^3 (``strain_energy``: u -> W per tet)."""
    t0 = time.perf_counter()
    u0 = predict()
    t1 = time.perf_counter()
    start = system.start(name, u0, t1 - t0)
    t2 = time.perf_counter()
    u, residual, nodes = system.patched(start, threshold=threshold, layers=layers)
    t3 = time.perf_counter()
    alone = Score(
        name, relative_strain_energy_error(strain_energy(start.u), W_ref), t2 - t0, start.residual
    )
    patched = Score(
        f"{name}+patch",
        relative_strain_energy_error(strain_energy(u), W_ref),
        t3 - t0,
        residual,
        nodes,
    )
    return alone, patched
