"""Online PGD: reduce a state to (s, Q, r, g), evaluate the modes, enrich when the state left.

Evaluation is a few interpolations and one (n_modes, D) vector-matrix product. Enrichment needs
the FEM operator of the current topology and an error indicator of the PGD answer:

- ``"energy"`` (default): the estimated relative strain-energy error -- W of the answer against W
  after a few Jacobi-preconditioned CG iterations of the FEM system started from it (the
  equilibrium guard's ``correct``). The PGD error sits next to the source, where those iterations
  act first, and it is measured in the paper's own metric.
- ``"residual"``: the global equilibrium residual ||f - K u|| / ||f||, blind to where the error is
  (benchmarks/results/pgd.md: states below 0.3 with 43 % strain-energy error).

Above the tolerance one FEM solve, warm-started from the answer, gives the correction, which
becomes a new online mode (per unit strength, centred on this state) -- the next similar state is
then cheap again.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Literal

import numpy as np

from diathermy.mesh import Grid, TetMesh
from diathermy.physics.equilibrium_guard import GuardPreconditioners, correct, relative_residual
from diathermy.physics.mechanics import MechanicsSolver
from diathermy.physics.strain_energy import relative_strain_energy_error, strain_energy_density
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


EnrichCriterion = Literal["energy", "residual"]
INDICATOR_ITERATIONS = 10
"""CG iterations of the strain-energy indicator (benchmarks/results/pgd.md: 5 / 10 / 20 compared)."""


def equilibrium_residual(
    solver: MechanicsSolver, u: np.ndarray, pressure_pa: np.ndarray, p0_pa: float
) -> float:
    """||f - K u|| / ||f|| over the free DOFs of u (n_nodes, 3) m under pressure (n_nodes,) Pa."""
    f = solver.load(pressure_pa, p0_pa).reshape(-1, 3)
    Ku = (solver.K @ np.asarray(u, float).ravel()).reshape(-1, 3)
    return relative_residual(f, Ku, ~solver.constrained.reshape(-1, 3))


@dataclass(frozen=True)
class Indicator:
    """An error indicator of a displacement: its value, the CG-continued u (n_nodes, 3) m, time s.

    ``u`` is the better answer the indicator computed on the way (the input itself for the
    residual, which computes none); ``iterations`` the CG iterations it ran.
    """

    value: float
    u: np.ndarray
    iterations: int
    seconds: float


def strain_energy_indicator(
    solver: MechanicsSolver,
    u: np.ndarray,
    pressure_pa: np.ndarray,
    p0_pa: float,
    iterations: int = INDICATOR_ITERATIONS,
) -> Indicator:
    """Estimated relative strain-energy error of u (n_nodes, 3) m under pressure (n_nodes,) Pa.

    ``relative_strain_energy_error(W(u), W(u_k))`` with u_k after ``iterations`` Jacobi-
    preconditioned CG iterations of ``solver``'s FEM system started from u: 0 when u is the FEM
    solution, and it tends to the true error as u_k tends to the solution. W with the solver's E
    (removed tissue at the ersatz modulus) and Poisson ratio.
    """
    t0 = time.perf_counter()
    corr = correct(
        solver,
        u,
        pressure_pa,
        p0_pa,
        tol=0.0,
        maxiter=int(iterations),
        preconditioner=GuardPreconditioners("jacobi"),
    )
    grads, tets = solver.assembler.geom.grads, solver.mesh.tets
    E, nu = solver.youngs_modulus_pa, solver.poisson_ratio
    value = relative_strain_energy_error(
        strain_energy_density(grads, tets, np.asarray(u, float), E, nu),
        strain_energy_density(grads, tets, corr.u, E, nu),
    )
    return Indicator(value, corr.u, corr.iterations, time.perf_counter() - t0)


def enrichment_indicator(
    criterion: EnrichCriterion,
    solver: MechanicsSolver,
    u: np.ndarray,
    pressure_pa: np.ndarray,
    p0_pa: float,
    iterations: int = INDICATOR_ITERATIONS,
) -> Indicator:
    """The indicator ``criterion`` names, of u (n_nodes, 3) m: "energy" or "residual"."""
    if criterion == "energy":
        return strain_energy_indicator(solver, u, pressure_pa, p0_pa, iterations)
    if criterion == "residual":
        t0 = time.perf_counter()
        value = equilibrium_residual(solver, u, pressure_pa, p0_pa)
        return Indicator(value, np.asarray(u, float), 0, time.perf_counter() - t0)
    raise ValueError(f"enrichment criterion must be 'energy' or 'residual', got {criterion!r}")


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
    x0: np.ndarray | None = None,
) -> EnrichmentStep:
    """Solve the FEM from x0 (default the PGD answer) and store u - u_pgd as an online mode.

    x0 (n_nodes, 3) m: a better start, e.g. the indicator's CG-continued u (fewer iterations).
    """
    p0 = model.material["p_atm_pa"]
    before = equilibrium_residual(solver, u_pgd, pressure_pa, p0)
    t0 = time.perf_counter()
    res = solver.solve(pressure_pa, p0, x0=u_pgd if x0 is None else x0)
    mode = (res.u - u_pgd).ravel() / state.strength_pa_m3
    new = model.with_online_mode(mode, state.s, state.radius_m, state.g)
    dt = time.perf_counter() - t0
    after = equilibrium_residual(solver, res.u, pressure_pa, p0)
    return EnrichmentStep(new, res.u, before, after, dt, res.stats.iterations)
