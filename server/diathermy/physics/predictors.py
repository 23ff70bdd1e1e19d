"""Mechanics predictors: where a step's displacement starts from, and which start to take.

Two kinds of start, both Ritz-scaled (the multiple closest to the FEM answer in the energy
norm) on the step's own system K u = f:

- persistence ('previous'): the last step's displacement; free, and close in steady stepping;
- a network (``DisplacementPredictor``: the shipped CNN, or any later model), which needs no
  history but costs an inference.

``mechanics.predictor`` 'auto' takes the network where persistence has nothing (no previous
displacement: the first mechanics step, tissue that came to rest), persistence elsewhere: that is
where benchmarks/results/predictors.md measured each one best. As a safety net for jumps larger
than measured there, it also asks the network when persistence's scaled relative residual
exceeds ``switch_residual`` and keeps whichever start is nearer equilibrium.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal, Protocol

import numpy as np

from diathermy.physics.equilibrium_guard import relative_residual, ritz_scale

PredictorName = Literal["previous", "none", "auto"]

DEFAULT_SWITCH_RESIDUAL = 0.5
"""'auto' asks the network when persistence's scaled relative residual exceeds this (the largest
in the measured situations: 0.40, the erratic path on 33x33x65)."""


class DisplacementPredictor(Protocol):
    """A network's guess of the displacement (n_nodes, 3) m from nodal pressure (n_nodes,) Pa and
    level set (n_nodes,) m; ``u_prev`` (n_nodes, 3) m or None for a model that uses history."""

    name: str

    def predict(
        self, pressure_pa: np.ndarray, level_set_m: np.ndarray, u_prev: np.ndarray | None
    ) -> np.ndarray: ...


@dataclass(frozen=True)
class Start:
    """A Ritz-scaled start: u and K u (n_nodes, 3) m / N, the factor, its relative residual."""

    name: str
    u: np.ndarray
    Ku: np.ndarray
    ritz_scale: float
    residual: float
    predict_s: float = 0.0


def ritz_start(
    name: str,
    u0: np.ndarray,
    matvec: Callable[[np.ndarray], np.ndarray],
    f: np.ndarray,
    free: np.ndarray,
    predict_s: float = 0.0,
) -> Start:
    """``u0`` (n_nodes, 3) m, constrained DOFs zeroed and Ritz-scaled on K (``matvec``: u -> K u,
    both (n_nodes, 3)) and f (n_nodes, 3) N, with its relative residual over ``free``."""
    u = np.where(free, u0, 0.0)
    Ku = matvec(u)
    alpha = ritz_scale(f, Ku, u, free)
    u, Ku = alpha * u, alpha * Ku
    return Start(name, u, Ku, alpha, relative_residual(f, Ku, free), predict_s)


@dataclass(frozen=True)
class Choice:
    """The start taken (None: nothing to start from, solve in full), why, and the residual of
    every start that was looked at."""

    start: Start | None
    why: str
    considered: dict[str, float] = field(default_factory=dict)


def choose_start(
    predictor: PredictorName,
    *,
    u_prev: np.ndarray | None,
    network: Callable[[], np.ndarray] | None,
    network_name: str,
    matvec: Callable[[np.ndarray], np.ndarray],
    f: np.ndarray,
    free: np.ndarray,
    switch_residual: float = DEFAULT_SWITCH_RESIDUAL,
    unavailable: str | None = None,
) -> Choice:
    """The start of this step for ``predictor`` ('previous' or 'auto'; 'none' never predicts).

    ``network``: a call that returns the network's raw u (n_nodes, 3) m, None when there is no
    model (``unavailable`` says why; 'auto' then falls back to persistence, or a full solve).
    """
    has_prev = u_prev is not None and bool(np.any(u_prev))
    considered: dict[str, float] = {}
    prev = None
    if has_prev:
        assert u_prev is not None
        prev = ritz_start("previous", u_prev, matvec, f, free)
        considered["previous"] = prev.residual
    if predictor != "auto":
        why = "persistence" if prev is not None else "no previous displacement"
        return Choice(prev, why, considered)
    if prev is not None and prev.residual <= switch_residual:
        why = f"persistence residual {prev.residual:.2g} <= {switch_residual:g}"
        return Choice(prev, why, considered)
    situation = (
        "no previous displacement"
        if prev is None
        else f"persistence residual {prev.residual:.2g} > {switch_residual:g}"
    )
    if network is None:
        return Choice(prev, f"{situation}; {unavailable or 'no network'}", considered)
    t0 = time.perf_counter()
    u_net = network()
    net = ritz_start(network_name, u_net, matvec, f, free, time.perf_counter() - t0)
    considered[network_name] = net.residual
    if prev is not None and prev.residual <= net.residual:
        why = f"{situation}, {network_name} {net.residual:.2g}: persistence kept"
        return Choice(prev, why, considered)
    return Choice(net, f"{situation}: {network_name}", considered)
