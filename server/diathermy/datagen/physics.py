"""The high-fidelity physics of a scenario: FEM elastostatics and the level-set cut.

A thin adapter from ``physics.mechanics`` / ``physics.strain_energy`` / ``physics.levelset`` /
``physics.topology`` to ``ScenarioPhysics``; it holds no equation of its own. A tet is healthy
when the topology rule does not call it removed (at least half its volume at phi < 0) and it is
not a loose fragment. Removed tets take the ersatz modulus and carry no pore pressure.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from diathermy.datagen.config import DatagenConfig
from diathermy.fem.elastic import ElasticAssembler
from diathermy.mesh import Grid, TetMesh, build_tet_mesh
from diathermy.physics.levelset import (
    advance,
    front_speed,
    initial_level_set,
    reinitialize,
    tet_to_node,
)
from diathermy.physics.mechanics import MechanicsSolver, mechanics_assembler
from diathermy.physics.strain_energy import strain_energy_density
from diathermy.physics.topology import loose_fragments, removed_fraction, removed_tets


@lru_cache(maxsize=2)
def _mesh_and_assembler(
    shape: tuple[int, int, int], size_m: tuple[float, float, float]
) -> tuple[TetMesh, ElasticAssembler]:
    """The mesh and its elasticity assembler, built once per worker process and grid."""
    mesh = build_tet_mesh(Grid(shape, size_m=size_m))
    return mesh, mechanics_assembler(mesh)


@dataclass(frozen=True)
class FemPhysics:
    """``ScenarioPhysics`` by FEM; one instance per scenario (it caches the scenario's solver)."""

    mesh: TetMesh
    assembler: ElasticAssembler
    config: DatagenConfig
    # The solver of the current topology: its AMG hierarchy and warm start live for one
    # scenario only, so a scenario's samples never depend on which scenario ran before.
    _solver: dict[bytes, MechanicsSolver] = field(default_factory=dict, repr=False)

    def initial_level_set(self) -> np.ndarray:
        return initial_level_set(self.mesh.grid).ravel()

    def removed(self, phi: np.ndarray) -> np.ndarray:
        """Removed-tissue mask (n_tets,) of nodal phi (n_nodes,) in m."""
        return removed_tets(removed_fraction(phi, self.mesh.tets))

    def healthy_tets(self, phi: np.ndarray) -> np.ndarray:
        removed = self.removed(phi)
        if not removed.any():
            return ~removed
        return ~removed & ~loose_fragments(removed, self.mesh)

    def solver(self, removed: np.ndarray) -> MechanicsSolver:
        """The mechanics solver of this removed mask (rebuilt when the cut changes)."""
        key = np.packbits(removed).tobytes()
        if key not in self._solver:
            m = self.config.material
            E = np.where(removed, m.ersatz_stiffness_ratio, 1.0) * m.youngs_modulus_pa
            self._solver.clear()
            self._solver[key] = MechanicsSolver(
                self.mesh,
                E,
                m.poisson_ratio,
                healthy=~removed,
                ersatz_ratio=m.ersatz_stiffness_ratio,
                rtol=self.config.mechanics_rtol,
                assembler=self.assembler,
            )
        return self._solver[key]

    def solve(self, pressure_pa: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        solver = self.solver(self.removed(phi))
        u = solver.solve(pressure_pa, self.config.material.p_atm_pa).u
        W = strain_energy_density(
            self.assembler.geom.grads,
            self.mesh.tets,
            u,
            solver.youngs_modulus_pa,
            self.config.material.poisson_ratio,
        )
        return u, W

    def advance(self, phi: np.ndarray, strain_energy: np.ndarray, step: int) -> np.ndarray:
        grid, ls = self.mesh.grid, self.config.level_set
        volumes = self.assembler.geom.volumes
        W_nodes = tet_to_node(strain_energy, self.mesh.tets, volumes, self.mesh.n_nodes)
        F = front_speed(W_nodes, self.config.material.damage_kappa_j_per_m3, ls.v0_m_per_s)
        new = advance(phi.reshape(grid.shape), F, grid.spacing_m, self.config.dt_s, cfl=ls.cfl).phi
        if (step + 1) % ls.reinit_every == 0:
            new = reinitialize(new, grid.spacing_m)
        return new.ravel()


def fem_physics(config: DatagenConfig) -> FemPhysics:
    """The default ``PhysicsFactory``: FEM mechanics and the level set of ``config``."""
    mesh, assembler = _mesh_and_assembler(tuple(config.grid), tuple(config.block_m))
    return FemPhysics(mesh, assembler, config)
