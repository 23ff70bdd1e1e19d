"""Online PGD: reduce a state to (s, Q, r, g), evaluate the modes, enrich when the state left.

Evaluation is a few interpolations and one (n_modes, D) vector-matrix product. Enrichment needs
the FEM operator of the current topology: the equilibrium residual ||f - K u|| / ||f|| of the PGD
answer measures how far the state is from what the modes can represent; above the tolerance one
FEM solve, warm-started from the PGD answer, gives the correction, which becomes a new online mode
(per unit strength, centred on this state) -- the next similar state is then cheap again.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from diathermy.mesh import Grid, TetMesh
from diathermy.physics.mechanics import MechanicsSolver
from diathermy.physics.topology import contact_height
from diathermy.surrogates.pgd.model import PGDModel
from diathermy.surrogates.pgd.parameters import (
    equivalent_radius,
    healthy_node_weights,
    pressure_moments,
)


@dataclass(frozen=True)
class PGDState:
    """A state's PGD parameters: position s (m), strength Q (Pa m^3), radius r (m), kPCA g."""

    s: tuple[float, float]
    strength_pa_m3: float
    radius_m: float
    g: np.ndarray
    inside: bool  # every parameter within the training ranges
    topology_distance: float  # RMS band-feature distance to the nearest training level set


def reduce_state(
    model: PGDModel,
    mesh: TetMesh,
    grid: Grid,
    volumes: np.ndarray,
    *,
    pressure_pa: np.ndarray,
    level_set_m: np.ndarray,
    healthy: np.ndarray,
    position_m: tuple[float, float] | None = None,
) -> PGDState:
    """(s, Q, r, g) of nodal pressure (n_nodes,) Pa and level set (n_nodes,) m.

    s is the electrode position when given, else the overpressure's centroid (x, y); the bump
    centre is the contact point below s. ``volumes`` (n_tets,) m^3, ``healthy`` (n_tets,).
    """
    p0 = model.material["p_atm_pa"]
    dp = np.asarray(pressure_pa, dtype=float) - p0
    w = healthy_node_weights(mesh.tets, volumes, healthy, mesh.n_nodes)
    if position_m is None:
        wdp = w * np.maximum(dp, 0.0)
        total = wdp.sum()
        if total > 0:
            position_m = (
                float(wdp @ mesh.points[:, 0] / total),
                float(wdp @ mesh.points[:, 1] / total),
            )
        else:
            position_m = (float(np.median(model.s_x)), float(np.median(model.s_y)))
    x, y = position_m
    z = float(contact_height(np.asarray(level_set_m).reshape(grid.shape), grid, x, y))
    centre = np.array([x, y, z])
    q, rms = pressure_moments(dp, mesh.points, centre, w)
    r_range = (float(model.radius_m[0]), float(model.radius_m[-1]))
    r = equivalent_radius(rms, mesh.points, centre, w, r_range) if q > 0 else r_range[0]
    g = model.topology.transform(level_set_m)
    _, inside = model.clamp((x, y), r, g)
    return PGDState((x, y), q, r, g, inside, model.topology.distance(level_set_m))


def evaluate(model: PGDModel, state: PGDState, n_modes: int | None = None) -> np.ndarray:
    """u (n_nodes, 3) in m = Q * U(s, r, g), online modes included."""
    if state.strength_pa_m3 == 0.0:
        return np.zeros((model.M.shape[1] // 3, 3))
    return state.strength_pa_m3 * model.unit_displacement(state.s, state.radius_m, state.g, n_modes)


def equilibrium_residual(
    solver: MechanicsSolver, u: np.ndarray, pressure_pa: np.ndarray, p0_pa: float
) -> float:
    """||f - K u|| / ||f|| of a displacement (n_nodes, 3) m under nodal pressure (n_nodes,) Pa."""
    f = solver.load(pressure_pa, p0_pa)
    nf = float(np.linalg.norm(f))
    if nf == 0.0:
        return 0.0 if not np.any(u) else float("inf")
    return float(np.linalg.norm(f - solver.K @ np.asarray(u, float).ravel())) / nf


@dataclass(frozen=True)
class EnrichmentStep:
    """One online enrichment: the enriched model, the FEM-exact u, residuals and time (s)."""

    model: PGDModel
    u: np.ndarray
    residual_before: float
    residual_after: float
    solve_s: float
    iterations: int


def enrich(
    model: PGDModel,
    solver: MechanicsSolver,
    state: PGDState,
    u_pgd: np.ndarray,
    pressure_pa: np.ndarray,
) -> EnrichmentStep:
    """Solve the FEM from the PGD answer and store the correction as one more online mode."""
    p0 = model.material["p_atm_pa"]
    before = equilibrium_residual(solver, u_pgd, pressure_pa, p0)
    t0 = time.perf_counter()
    res = solver.solve(pressure_pa, p0, x0=u_pgd)
    mode = (res.u - u_pgd).ravel() / state.strength_pa_m3
    new = model.with_online_mode(mode, state.s, state.radius_m, state.g)
    dt = time.perf_counter() - t0
    after = equilibrium_residual(solver, res.u, pressure_pa, p0)
    return EnrichmentStep(new, res.u, before, after, dt, res.stats.iterations)
