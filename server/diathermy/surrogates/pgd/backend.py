"""``PGDBackend``: the PGD model behind the engine's ``MechanicsBackend`` interface.

Without a tolerance it only evaluates the modes (no FEM operator is ever built). With
``enrich_tol`` it also builds the FEM operator of the current topology (rebuilt only when the
topology changes), evaluates the enrichment indicator of every answer (``online``: by default the
estimated strain-energy error after a few CG iterations; or the equilibrium residual) and, above
the tolerance, adds an online mode from one warm-started FEM solve (the answer is then the FEM's).
Below it the answer is the PGD's own, not the indicator's CG-continued one.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from diathermy.fem.geometry import structured_geometry
from diathermy.mesh import Grid, TetMesh
from diathermy.physics.mechanics_backend import FEMBackend, MechanicsOutput
from diathermy.surrogates.pgd.model import PGDModel
from diathermy.surrogates.pgd.online import (
    INDICATOR_ITERATIONS,
    EnrichCriterion,
    enrich,
    enrichment_indicator,
    equilibrium_residual,
    evaluate,
    reduce_state,
)


class PGDBackend:
    """Hybrid-PGD mechanics: u = Q sum_i M_i N_i(s) R_i(r) S_i(g), optionally enriched online.

    Args:
        model: a built (or loaded) model of this mesh's grid.
        mesh, grid: the engine's tet mesh and its grid.
        n_modes: use only the first n offline modes (all by default).
        enrich_tol: indicator value above which a mode is added; None: never enrich.
        enrich_criterion: "energy" (estimated relative strain-energy error, the default) or
            "residual" (relative equilibrium residual ||f - K u|| / ||f||).
        indicator_iterations: CG iterations of the "energy" indicator.
        position_fn: the electrode position (x, y) m of the current step, or None to take the
            overpressure's centroid.
        rtol: CG tolerance of the enrichment solves.
    """

    name = "pgd"

    def __init__(
        self,
        model: PGDModel,
        mesh: TetMesh,
        grid: Grid,
        *,
        n_modes: int | None = None,
        enrich_tol: float | None = None,
        enrich_criterion: EnrichCriterion = "energy",
        indicator_iterations: int = INDICATOR_ITERATIONS,
        position_fn: Callable[[], tuple[float, float] | None] | None = None,
        rtol: float = 1e-6,
    ) -> None:
        self.model = model
        self.mesh = mesh
        self.grid = grid
        self.n_modes = n_modes
        self.enrich_tol = enrich_tol
        if enrich_criterion not in ("energy", "residual"):
            raise ValueError(
                f"enrich_criterion must be 'energy' or 'residual': {enrich_criterion!r}"
            )
        self.enrich_criterion = enrich_criterion
        self.indicator_iterations = int(indicator_iterations)
        self.position_fn = position_fn
        self.volumes = structured_geometry(mesh.points, mesh.tets, mesh.shape_id).volumes
        mat = model.material
        self._fem = FEMBackend(
            mesh,
            poisson_ratio=mat["poisson_ratio"],
            p0_pa=mat["p_atm_pa"],
            rtol=rtol,
            ersatz_ratio=mat["ersatz_stiffness_ratio"],
        )
        self.n_enriched = 0
        self.enrich_seconds: list[float] = []

    def solve(
        self,
        *,
        pressure_pa: np.ndarray,
        level_set_m: np.ndarray,
        youngs_modulus_pa: np.ndarray,
        healthy: np.ndarray,
        warm_start: np.ndarray | None,
    ) -> MechanicsOutput:
        del warm_start  # the PGD answer needs none
        t0 = time.perf_counter()
        position = self.position_fn() if self.position_fn is not None else None
        state = reduce_state(
            self.model,
            self.mesh,
            self.grid,
            self.volumes,
            pressure_pa=pressure_pa,
            level_set_m=level_set_m,
            healthy=healthy,
            position_m=position,
        )
        u = evaluate(self.model, state, self.n_modes)
        extra: dict[str, float | int | bool] = {
            "modes": self.model.n_modes
            if self.n_modes is None
            else min(self.n_modes, self.model.n_modes),
            "online_modes": self.model.n_online,
            "inside_manifold": state.inside,
            "topology_distance": state.topology_distance,
            "strength_pa_m3": state.strength_pa_m3,
            "radius_m": state.radius_m,
            "eval_s": time.perf_counter() - t0,
            "residual_checked": False,
            "enriched": False,
        }
        residual = 0.0
        iterations = 0
        rebuilt = False
        if self.enrich_tol is not None and state.strength_pa_m3 > 0:
            t1 = time.perf_counter()
            solver, rebuilt = self._fem.operator_for(youngs_modulus_pa, healthy)
            extra["operator_s"] = time.perf_counter() - t1
            ind = enrichment_indicator(
                self.enrich_criterion,
                solver,
                u,
                pressure_pa,
                self.model.material["p_atm_pa"],
                self.indicator_iterations,
            )
            extra.update(residual_checked=True, indicator=ind.value, indicator_s=ind.seconds)
            if ind.value > self.enrich_tol:
                step = enrich(self.model, solver, state, u, pressure_pa, x0=ind.u)
                self.model = step.model
                u, residual, iterations = step.u, step.residual_after, step.iterations
                self.n_enriched += 1
                self.enrich_seconds.append(step.solve_s)
                extra.update(enriched=True, enrich_s=step.solve_s, online_modes=self.model.n_online)
            else:
                residual = equilibrium_residual(
                    solver, u, pressure_pa, self.model.material["p_atm_pa"]
                )
        return MechanicsOutput(
            u=u, iterations=iterations, residual=residual, rebuilt=rebuilt, extra=extra
        )
