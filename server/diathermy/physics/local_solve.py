"""The local path of incremental mechanics: its settings and the patch-corrected prediction.

A predicted displacement (``predictors.Start``: Ritz-scaled previous step or network) is
corrected by the residual patch solve where its residual concentrates (``patch_correction``),
round after round until the guard's residual is met or the patch finds nothing to correct.
``incremental_mechanics`` decides whether the answer stands, is polished or is solved in full.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp

from diathermy.physics.mechanics import MechanicsSolver
from diathermy.physics.patch_correction import patch_correct, residual_patch
from diathermy.physics.predictors import DEFAULT_SWITCH_RESIDUAL, Start

DEFAULT_GUARD_TOLERANCE = 1e-2
"""Relative residual the local path must reach: on the 9x9x17 test block with a cut, max
strain-energy error 0.33 % and max temperature error 0.005 K against full solves (1e-3: mostly
full solves; 3e-2: 0.83 %); the default grids: benchmarks/results/realtime.md."""
DEFAULT_ENERGY_TOLERANCE = 1e-3
"""Relative energy-norm error estimate (``fem.energy_cg``) a polished answer must reach. The
estimate reads 0.2-0.5x the true error (benchmarks/results/guard_estimate.md), so this admits
true relative energy errors of about 2-5e-3. Whole runs from step 0 against the full solve at
every step (docs/realtime.md, *Whole runs*): 3e-3 left the full trajectory after 33-97 steps on
the fixed electrode's 0.4 mm grid (a tet cut a step apart; up to 61 % strain energy, 9.9 K) and
after 25 on the moving electrode; 1e-3 kept max 4e-4 and 0.018 K over the 100 steps of the
default, fixed- and moving-electrode scenes. The scene model's default."""
DEFAULT_POLISH_ITERATIONS = 20
"""PCG iterations with the kept hierarchy before the step falls back to the full solve (the
fixed electrode's 0.4 mm grid polishes in 4-9 with the degree-1 V-cycle; a full solve takes 27-116)."""
DEFAULT_WINDOW_M = 0.016
"""Margin of the windowed polish around the patch (``polish_window``): on the default graded
grid's cutting steps 97-99 % of the patched prediction's error energy lies within 16 mm of it
(docs/realtime.md)."""
DEFAULT_INTERVAL_TOLERANCE = 3e-4
"""Relative energy-norm error estimate the interval's global solve reaches (every ``full_every``
solves, from the local path's answer, with the kept hierarchy): a tenth of the step's
``energy_tolerance``, so the far-field error that builds up between intervals is reset, for a
fraction of the FEM tolerance's iterations (docs/realtime.md). 0: the FEM solve to its residual
tolerance."""
INTERVAL_MAX_ITERATIONS = 150
"""PCG iterations the interval's global solve may take before the FEM solve takes over."""
DEFAULT_WINDOW_HISTORY = 0
"""Past displacements the windowed polish solves for with its window (``polish_window``); 0, the
window alone, stays the default. With 4, in one lockstep run of 8 cutting steps, the fixed
electrode's median step fell from 2.58 to 1.56 s (its global polish from 4-12 PCG iterations to
0-1) inside the error targets, but over a whole 100-step run a tet was cut a step apart at step
96 (0.37 K after it), where the window alone held the full trajectory; with energy_tolerance
5e-4 it held all 100 steps at 0.82x the default's median step, but the moving electrode's
100-step run left the full trajectory at step 24 (0.115 K) with it, at 1.03x the default's median
step (docs/realtime.md, *The window and the history*)."""
MAX_WINDOW_HISTORY = 16
"""The most past displacements the window may be augmented with (each is a global vector)."""
WINDOW_MAX_FRACTION = 0.25
"""The window holds at most this share of the nodes (its margin is halved until it does)."""
Guard = Literal["residual", "energy"]


@dataclass(frozen=True)
class IncrementalSettings:
    """Knobs of the local path: the residual it must reach, the full-solve interval, the patch."""

    guard_tolerance: float = DEFAULT_GUARD_TOLERANCE
    full_every: int = 10
    patch_threshold: float = 0.1
    patch_layers: int = 2
    patch_max_nodes: int = 4000
    patch_rounds: int = 1  # 3 passed the guard at 23 % SE error on 0.4 mm: docs/realtime.md
    patch: bool = True  # mechanics.correction: 'patch', or 'none' (the Ritz-scaled start as is)
    switch_residual: float = DEFAULT_SWITCH_RESIDUAL  # predictor 'auto': when to ask the network
    guard: Guard = "residual"  # 'energy': only the polish's energy estimate accepts a step
    energy_tolerance: float = DEFAULT_ENERGY_TOLERANCE
    polish_iterations: int = DEFAULT_POLISH_ITERATIONS  # 0: no polish, the full solve
    window_m: float = DEFAULT_WINDOW_M  # the windowed polish's margin; 0: none
    window_iterations: int = 30
    window_share: float = 0.3  # the window's tolerance: this x energy_tolerance
    window_history: int = DEFAULT_WINDOW_HISTORY  # past displacements solved for with the window
    interval_tolerance: float = DEFAULT_INTERVAL_TOLERANCE  # 0: the interval solves FEM-tight

    def __post_init__(self) -> None:
        if not self.guard_tolerance > 0 or self.full_every < 1 or self.patch_rounds < 1:
            raise ValueError("guard_tolerance must be > 0, full_every and patch_rounds >= 1")
        if not 0 < self.energy_tolerance < 1 or self.polish_iterations < 0:
            raise ValueError("energy_tolerance must lie in (0, 1), polish_iterations be >= 0")
        if not self.window_m >= 0 or self.window_iterations < 1 or not 0 < self.window_share <= 1:
            raise ValueError(
                "window_m must be >= 0, window_iterations >= 1, window_share in (0, 1]"
            )
        if not 0 <= self.window_history <= MAX_WINDOW_HISTORY:
            raise ValueError(f"window_history must lie in [0, {MAX_WINDOW_HISTORY}]")
        if not 0 <= self.interval_tolerance < 1:
            raise ValueError("interval_tolerance must lie in [0, 1)")
        if self.guard not in ("residual", "energy"):
            raise ValueError(f"guard must be 'residual' or 'energy', got {self.guard!r}")


@dataclass(frozen=True)
class LocalSolve:
    """The predictor's answer: u (n_nodes, 3) m, its residual, the patch size, the Ritz factor."""

    u: np.ndarray
    residual: float
    residual_before: float
    patch_nodes: np.ndarray  # nodes where u is not ritz_scale x the start
    ritz_scale: float
    predictor: str = "previous"
    Ku: np.ndarray | None = None  # K u (n_nodes, 3) N, kept up to date through the patch


def local_solve(
    solver: MechanicsSolver,
    start: Start,
    f: np.ndarray,
    graph: sp.csr_matrix,
    settings: IncrementalSettings,
    u_prev: np.ndarray | None = None,
) -> LocalSolve:
    """``start`` (Ritz-scaled, ``predictors.ritz_start``) patch-corrected on ``solver``'s system
    with load f (n_nodes, 3) N; residuals over the free DOFs. ``u_prev`` (n_nodes, 3) m: the
    warm start, whose constrained values the start zeroed (they count as moved)."""
    free = ~solver.constrained.reshape(-1, 3)
    u, Ku = start.u, start.Ku
    moved = np.zeros(0, dtype=np.int64)
    first = after = start.residual
    for _ in range(settings.patch_rounds if settings.patch else 0):
        # each round patches where the last one left off
        nodes = residual_patch(
            np.where(free, f - Ku, 0.0),
            graph,
            threshold=settings.patch_threshold,
            layers=settings.patch_layers,
            max_nodes=settings.patch_max_nodes,
        )
        patched = patch_correct(solver.K, f, u, Ku, free, nodes)
        u, Ku, after = patched.u, patched.Ku, patched.residual_after
        if patched.nodes:
            moved = np.union1d(moved, nodes)
        if after <= settings.guard_tolerance or not patched.nodes:
            break
    if u_prev is not None:
        held = np.flatnonzero(np.any(~free & (u_prev != 0), axis=1))  # zeroed constrained values
        moved = np.union1d(moved, held)
    return LocalSolve(u, after, first, moved, start.ritz_scale, start.name, Ku)
