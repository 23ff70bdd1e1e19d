"""One scenario of Algorithm 1: the walk, the nodal pressure, the mechanics solve, the level set."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from diathermy.datagen.config import DatagenConfig
from diathermy.datagen.pressure import nodal_pressure
from diathermy.datagen.walk import (
    Move,
    draw_pressure,
    legacy_numpy_seed,
    next_move,
    perturb,
    scenario_rng,
    start_tets,
    surface_tets,
)
from diathermy.fem.geometry import structured_geometry
from diathermy.mesh import TetMesh


class ScenarioPhysics(Protocol):
    """What a scenario needs from the physics: level set, healthy tets, solve, advance."""

    @property
    def mesh(self) -> TetMesh: ...

    def initial_level_set(self) -> np.ndarray:
        """phi (n_nodes,) in m at the start of every scenario."""
        ...

    def healthy_tets(self, phi: np.ndarray) -> np.ndarray:
        """Bool mask (n_tets,) of tets still healthy under phi (n_nodes,)."""
        ...

    def solve(self, pressure_pa: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Displacement (n_nodes, 3) in m and strain energy (n_tets,) in J/m^3."""
        ...

    def advance(self, phi: np.ndarray, strain_energy: np.ndarray, step: int) -> np.ndarray:
        """phi (n_nodes,) after one step dt under the strain energy (n_tets,)."""
        ...


PhysicsFactory = Callable[[DatagenConfig], ScenarioPhysics]
"""Builds the physics of a config; must be picklable (a module-level function) for workers."""


@dataclass(frozen=True)
class Sample:
    """One step of one scenario: the walk's move and the nodal fields (flat node order)."""

    scenario: int
    step: int
    move: Move
    p_tet_pa: np.ndarray  # (n_tets,) Gauss-point pressures after this step's draws
    pressure_pa: np.ndarray  # (n_nodes,)
    level_set_m: np.ndarray  # (n_nodes,) the phi the solve saw
    displacement_m: np.ndarray  # (n_nodes, 3)


def scenario_start(config: DatagenConfig, mesh: TetMesh, index: int) -> int:
    """The top-surface tet scenario ``index`` starts from."""
    return int(start_tets(surface_tets(mesh), config.seed, index + 1)[index])


def run_scenario(config: DatagenConfig, index: int, physics: ScenarioPhysics) -> Iterator[Sample]:
    """Yield the ``config.n_steps`` samples of scenario ``index`` (Algorithm 1).

    pyamg draws the start vectors of its spectral-radius estimates from numpy's global RNG, so
    the AMG hierarchies (and the last bits of every solve) depend on it: it is seeded from
    (seed, index) here, so a scenario gives the same bits in any process and after any other
    scenario. Do not interleave two of these generators in one process.
    """
    np.random.seed(legacy_numpy_seed(config.seed, index))  # noqa: NPY002
    mesh = physics.mesh
    rng = scenario_rng(config.seed, index)
    lo, hi, p0 = config.p_min_pa, config.p_max_pa, config.material.p_atm_pa
    volumes = structured_geometry(mesh.points, mesh.tets, mesh.shape_id).volumes
    p_tet = np.full(mesh.n_tets, p0)
    phi = physics.initial_level_set()
    visited: list[int] = []
    visited_set: set[int] = set()
    for step in range(config.n_steps):
        if step == 0:
            move = Move(scenario_start(config, mesh, index), -1)
        else:
            healthy = physics.healthy_tets(phi)
            move = next_move(visited, visited_set, mesh.neighbours, healthy, rng)
        p_new = draw_pressure(rng, lo, hi) if move.tet >= 0 else p0
        if visited:
            p_tet[visited] = perturb(p_tet[visited], rng, config.perturbation, lo, hi)
        if move.tet >= 0:
            p_tet[move.tet] = p_new
            visited.append(move.tet)
            visited_set.add(move.tet)
        pressure = nodal_pressure(mesh.tets, volumes, p_tet, p0, mesh.n_nodes)
        u, strain_energy = physics.solve(pressure, phi)
        yield Sample(index, step, move, p_tet.copy(), pressure, phi, u)
        if step + 1 < config.n_steps:
            phi = physics.advance(phi, strain_energy, step)
