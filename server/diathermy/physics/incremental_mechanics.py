"""Incremental FEM mechanics: a predicted displacement, checked and corrected.

The prediction is the previous displacement, or with ``mechanics.predictor`` 'auto' a
network's where that has nothing or is far off (``predictors``). Between two steps the pore
pressure changes on a few hot nodes and a few tets are cut, so the last displacement is nearly
the new one. Each step it is Ritz-scaled (the multiple closest in the energy norm) and
corrected by the patch solve where its residual concentrates (the crater wall,
``patch_correction``). The guard then decides:

- ``residual``: accepted when the relative equilibrium residual ||f - K u|| / ||f|| of the
  *new* system (one sparse mat-vec) is at most ``guard_tolerance``;
- otherwise, and always with the ``energy`` guard, it is *polished*: first on a window of nodes
  around the patch with the rest held (``polish_window``, ``window_m``; its own kept hierarchy),
  then PCG with the kept global AMG hierarchy (``fem.energy_cg``, at most ``polish_iterations``,
  none when the window's answer passes) until the estimated relative energy-norm error
  sqrt(r.Mr) / ||u||_K is at most ``energy_tolerance``.

What passes neither CG solves in full from it to the FEM tolerance. Every ``full_every`` solves
the interval's global solve resets the error that builds up outside the window: PCG with the kept
hierarchy on the whole block, from the local answer, to ``interval_tolerance`` (a tenth of the
step's by default; 0, or a PCG that does not get there: the FEM solve). On fine graded grids a
small residual does not bound the error (the residual guard let 57 % strain-energy errors
through, docs/realtime.md), so 'auto' picks the energy guard there. Each answer says which path
it took and why (``extra["mode"]``: 'local' for an accepted prediction, 'full'; ``["why"]``) and
which predictor started it (``["predictor"]``, ``["predictor_why"]``).
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from diathermy.fem.energy_cg import EnergyCG, energy_cg
from diathermy.physics.local_solve import (
    INTERVAL_MAX_ITERATIONS,
    IncrementalSettings,
    LocalSolve,
    local_solve,
)
from diathermy.physics.mechanics import MechanicsSolver
from diathermy.physics.mechanics_backend import FEMBackend, MechanicsOutput, Rescaled
from diathermy.physics.patch_correction import node_graph
from diathermy.physics.polish_window import PolishWindow, WindowedPolish
from diathermy.physics.predictors import (
    DisplacementPredictor,
    PredictorName,
    Start,
    choose_start,
)


class IncrementalFEMBackend:
    """The FEM backend started from a predictor (``mechanics.predictor`` 'previous': the last
    displacement; 'auto': a network where persistence has nothing or is far off, see
    ``predictors``); the full solve is ``fem``'s, with its kept operator and AMG hierarchy.

    ``network``: the model 'auto' may ask (None: none for this grid, ``network_unavailable``
    says why; 'auto' then falls back to persistence or a full solve and reports that reason).
    """

    name = "fem"

    def __init__(
        self,
        fem: FEMBackend,
        settings: IncrementalSettings,
        *,
        predictor: PredictorName = "previous",
        network: DisplacementPredictor | None = None,
        network_unavailable: str | None = None,
    ) -> None:
        self.fem = fem
        self.settings = settings
        self.predictor: PredictorName = predictor
        self.network = network
        self.network_unavailable = network_unavailable
        self._graph: sp.csr_matrix | None = None
        self.since_full = 0
        self.n_local = 0
        self.n_full = 0
        self._forced: str | None = None
        self.last_E_pa: np.ndarray | None = None  # E per tet of the solve behind the warm start
        self.windowed = WindowedPolish(settings)
        # the last answers (n_nodes, 3) m, newest first: the window's history (window_history)
        self.history: list[np.ndarray] = []

    def remember(self, u: np.ndarray) -> None:
        """Keep ``u`` as the newest of the window's history (at most ``window_history``)."""
        m = self.settings.window_history
        self.history = [np.array(u, dtype=float)] + self.history[: m - 1] if m > 0 else []

    def force_full(self, why: str) -> None:
        """Solve the next step in full, saying ``why``."""
        self._forced = why

    def full_reason(self, warm_start: np.ndarray | None) -> str | None:
        """Why this step must solve in full (None: the local path may serve)."""
        if self._forced is not None:
            return f"forced: {self._forced}"
        if warm_start is None or not np.any(warm_start):
            if self.predictor != "auto":
                return "no previous displacement to start from"
            if self.network is None:
                return (
                    "no previous displacement to start from; "
                    f"{self.network_unavailable or 'no network'}"
                )
        if self.since_full + 1 >= self.settings.full_every:
            return f"interval: a full solve every {self.settings.full_every} solves"
        return None

    def _start(
        self,
        solver: MechanicsSolver,
        f: np.ndarray,
        pressure_pa: np.ndarray,
        level_set_m: np.ndarray,
        warm_start: np.ndarray | None,
    ) -> tuple[Start | None, str, dict[str, float]]:
        """The predictor's start for this step, why, and the residuals of the starts looked at."""
        net = self.network
        free = ~solver.constrained.reshape(-1, 3)
        choice = choose_start(
            self.predictor,
            u_prev=warm_start,
            network=None
            if net is None
            else (lambda: net.predict(pressure_pa, level_set_m, warm_start)),
            network_name=net.name if net is not None else "network",
            matvec=lambda u: (solver.K @ u.ravel()).reshape(-1, 3),
            f=f,
            free=free,
            switch_residual=self.settings.switch_residual,
            unavailable=self.network_unavailable,
        )
        return choice.start, choice.why, choice.considered

    def _local(
        self, solver: MechanicsSolver, start: Start, f: np.ndarray, warm_start: np.ndarray | None
    ) -> LocalSolve:
        """The start Ritz-scaled and patch-corrected on this system (``local_solve``)."""
        if self._graph is None:
            self._graph = node_graph(solver.K)  # the mesh's pattern: built once
        u_prev = warm_start if start.name == "previous" else None
        return local_solve(solver, start, f, self._graph, self.settings, u_prev)

    def _newest_product(self, start: Start, warm_start: np.ndarray | None) -> np.ndarray | None:
        """K times the newest history entry (n_nodes, 3) N, its constrained values zeroed as the
        history's are, from the Ritz-scaled start when that started from it (None: the
        window's history computes it)."""
        if (
            start.name != "previous"
            or start.ritz_scale == 0
            or not self.history
            or warm_start is None
            or not np.array_equal(self.history[0], warm_start)
        ):
            return None
        return start.Ku / start.ritz_scale

    @property
    def window(self) -> PolishWindow | None:
        """The windowed polish's kept window (None: none yet, or it went stale)."""
        return self.windowed.window

    def restore_window(
        self, box: np.ndarray, youngs_modulus_pa: np.ndarray, healthy: np.ndarray
    ) -> None:
        """Rebuild the window a checkpoint saved (its box (4, 3) m and the topology its
        hierarchy was built for), so the next polish repeats the original run's."""
        self.windowed.restore(self.fem.fresh_operator(youngs_modulus_pa, healthy), box)

    def _polish(
        self,
        solver: MechanicsSolver,
        f: np.ndarray,
        u: np.ndarray,
        residual: np.ndarray | None = None,
        *,
        interval: bool = False,
    ) -> EnergyCG | None:
        """PCG from u (n_nodes, 3) m with the kept hierarchy until the energy-error estimate
        passes ``energy_tolerance`` (``interval``: ``interval_tolerance``, within
        ``INTERVAL_MAX_ITERATIONS``), on the Jacobi-scaled system (``residual``: its b - A x
        when known); None when there is no hierarchy to keep (the full solve builds one) or
        polishing is off."""
        M = solver.krylov.kept_preconditioner
        A = solver.krylov.A
        st = self.settings
        if M is None or A is None or st.polish_iterations == 0:
            return None
        s = solver.scale
        return energy_cg(
            A,
            f.ravel() * s,
            u.ravel() / s,
            M,
            tol=st.interval_tolerance if interval else st.energy_tolerance,
            maxiter=INTERVAL_MAX_ITERATIONS if interval else st.polish_iterations,
            residual=residual,
        )

    def _accept(
        self,
        solver: MechanicsSolver,
        u: np.ndarray,
        residual: float,
        rebuilt: bool,
        local: LocalSolve,
        moved: np.ndarray | None,
        extra: dict[str, float | int | bool | str],
        iterations: int = 0,
        interval: bool = False,
    ) -> MechanicsOutput:
        """The predictor's answer u (n_nodes, 3) m taken as this step's; ``moved``: u is the
        Ritz-scaled warm start but on these nodes (the patch, the window), so its strain energy
        is updated there, not recomputed; None: u moved everywhere. ``interval``: the answer is
        the interval's global solve (``interval_tolerance``), which restarts the count."""
        if interval:
            self.since_full = 0
            self.n_full += 1
        else:
            self.since_full += 1
            self.n_local += 1
        loose = solver.fragments.loose
        previous_E, self.last_E_pa = self.last_E_pa, solver.youngs_modulus_pa
        extra.update(mode="full" if interval else "local")
        self.remember(u)
        return MechanicsOutput(
            u=u,
            iterations=iterations,
            residual=residual,
            rebuilt=rebuilt,
            loose_tets=loose if loose.any() else None,
            rescaled=None
            if previous_E is None or moved is None
            else Rescaled(local.ritz_scale, moved, previous_E),
            extra=extra,
        )

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
        # the interval's global solve: from the local path's answer to interval_tolerance
        interval = why if why is not None and why.startswith("interval") else None
        if interval is not None and self.settings.interval_tolerance > 0:
            why = None
        else:
            interval = None
        extra: dict[str, float | int | bool | str] = {"operator_s": operator_s, "predictor": "none"}
        x0 = warm_start
        if why is None:
            f = solver.load(pressure_pa, self.fem.p0_pa).reshape(-1, 3)
            start, picked, considered = self._start(solver, f, pressure_pa, level_set_m, warm_start)
            extra.update(predictor_why=picked)
            extra.update({f"residual_{k}": v for k, v in considered.items()})
            if start is None:
                why = picked
        if why is None:
            assert start is not None
            persistence = start.name == "previous"
            local = self._local(solver, start, f, warm_start)
            extra.update(
                predictor=start.name,
                residual_before=local.residual_before,
                patch_nodes=int(local.patch_nodes.size),
                ritz_scale=local.ritz_scale,
                predict_s=start.predict_s,
                local_s=time.perf_counter() - t0 - operator_s,
            )
            tol = self.settings.guard_tolerance
            if self.settings.guard == "residual" and local.residual <= tol and not interval:
                extra.update(why=f"residual {local.residual:.1e} <= {tol:.0e}", guard_tolerance=tol)
                moved = local.patch_nodes if persistence else None
                return self._accept(solver, local.u, local.residual, rebuilt, local, moved, extra)
            why = (
                interval
                if interval is not None
                else f"residual {local.residual:.1e} > {tol:.0e} after the patch"
                if self.settings.guard == "residual"
                else "energy guard"
            )
            u_window, r_window, window_nodes = self.windowed.correct(
                solver, f, local.u, local.Ku, local.patch_nodes, extra, self.history,
                self._newest_product(start, warm_start),
            )  # fmt: skip
            polished = self._polish(solver, f, u_window, r_window, interval=bool(interval))
            if polished is not None:
                st = self.settings
                etol = st.interval_tolerance if interval is not None else st.energy_tolerance
                extra.update(
                    polish_iterations=polished.iterations,
                    energy_estimate=polished.estimate,
                    energy_tolerance=etol,
                    local_s=time.perf_counter() - t0 - operator_s,
                )
                if polished.estimate <= etol and interval is not None:
                    extra.update(
                        why=f"{interval}: {polished.iterations} CG iterations on the whole block "
                        f"with the kept hierarchy: energy-error estimate {polished.estimate:.1e} "
                        f"<= {etol:.0e}"
                    )
                    u = (polished.x * solver.scale).reshape(-1, 3)
                    return self._accept(
                        solver, u, polished.residual, rebuilt, local, None, extra,
                        iterations=polished.iterations, interval=True,
                    )  # fmt: skip
                if polished.estimate <= etol:
                    extra.update(
                        why=f"{why}; {polished.iterations} CG iterations with the kept "
                        f"hierarchy: energy-error estimate {polished.estimate:.1e} <= {etol:.0e}",
                    )
                    moved = None
                    if polished.iterations == 0:  # the window's answer as it is
                        u = u_window
                        if persistence and window_nodes is not None:
                            moved = np.union1d(local.patch_nodes, window_nodes)
                    else:
                        u = (polished.x * solver.scale).reshape(-1, 3)
                    return self._accept(
                        solver, u, polished.residual, rebuilt, local, moved, extra,
                        iterations=polished.iterations,
                    )  # fmt: skip
                why = (
                    f"{why}; energy-error estimate {polished.estimate:.1e} > {etol:.0e} after "
                    f"{polished.iterations} CG iterations"
                )
                if interval is None:  # the interval's FEM solve starts from the last answer
                    x0 = (polished.x * solver.scale).reshape(-1, 3)
            else:
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
        self.remember(out.u)
        if extra["predictor"] == "none" and x0 is not None and np.any(x0):
            extra["predictor"] = "previous"  # CG started from the last displacement
        return MechanicsOutput(
            u=out.u,
            iterations=out.iterations,
            residual=out.residual,
            rebuilt=out.rebuilt or rebuilt,
            loose_tets=out.loose_tets,
            extra={**out.extra, **extra, "mode": "full", "why": why},
        )
