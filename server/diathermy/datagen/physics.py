"""The high-fidelity physics of a scenario: the engine's own mechanics and dissection steps.

A thin adapter to ``ScenarioPhysics`` that holds no equation of its own: the mechanics is
``physics.mechanics_backend.solve_with_cut`` (FEM, the cut as ersatz material) and the cut moves
by ``physics.dissection.dissection_step``, exactly the functions the engine's effects call, with
the same healthy rule (``physics.topology``: a tet is removed when at least half its volume is
cut, or when it is part of a loose fragment), the same ersatz modulus and the same level-set law
(the config's ``LevelSetConfig``). Like the engine, a step whose strain energy stays below kappa
does not move the cut and does not count towards re-initialisation.

One difference is deliberate: every sample is a fresh solve (no warm start from the previous
sample), so a stored sample can be reproduced from its stored inputs alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property, lru_cache

import numpy as np
import scipy.sparse as sp

from diathermy.datagen.config import DatagenConfig
from diathermy.fem.elastic import ElasticAssembler
from diathermy.mesh import Grid, TetMesh, build_tet_mesh
from diathermy.physics.dissection import cut_moves, dissection_step
from diathermy.physics.levelset import initial_level_set, volume_incidence
from diathermy.physics.mechanics import mechanics_assembler
from diathermy.physics.mechanics_backend import FEMBackend, solve_with_cut
from diathermy.physics.topology import Topology, evaluate_topology


@lru_cache(maxsize=2)
def _mesh_and_assembler(
    shape: tuple[int, int, int], size_m: tuple[float, float, float]
) -> tuple[TetMesh, ElasticAssembler]:
    """The mesh and its elasticity assembler, built once per worker process and grid."""
    mesh = build_tet_mesh(Grid(shape, size_m=size_m))
    return mesh, mechanics_assembler(mesh)


@dataclass
class FemPhysics:
    """``ScenarioPhysics`` by the engine's FEM steps; one instance per scenario (it holds the
    scenario's solver, its topology and its re-initialisation counter)."""

    mesh: TetMesh
    assembler: ElasticAssembler
    config: DatagenConfig
    # The solver of the current topology: its AMG hierarchy lives for one scenario only, so a
    # scenario's samples never depend on which scenario ran before.
    _topology: dict[bytes, Topology] = field(default_factory=dict, repr=False)
    _steps_since_reinit: int = 0

    @cached_property
    def backend(self) -> FEMBackend:
        m = self.config.material
        return FEMBackend(
            self.mesh,
            poisson_ratio=m.poisson_ratio,
            p0_pa=m.p_atm_pa,
            rtol=self.config.mechanics_rtol,
            ersatz_ratio=m.ersatz_stiffness_ratio,
            assembler=self.assembler,
        )

    @cached_property
    def incidence(self) -> sp.csr_matrix:
        return volume_incidence(self.mesh.tets, self.assembler.geom.volumes, self.mesh.n_nodes)

    def initial_level_set(self) -> np.ndarray:
        return initial_level_set(self.mesh.grid).ravel()

    def topology(self, phi: np.ndarray) -> Topology:
        """The topology of nodal phi (n_nodes,) in m (the last one is kept)."""
        key = np.asarray(phi, dtype=float).tobytes()
        if key not in self._topology:
            previous = next(iter(self._topology.values()), None)
            topo = evaluate_topology(phi, self.mesh, self.assembler.geom.volumes, previous)
            self._topology = {key: topo}
        return self._topology[key]

    def removed(self, phi: np.ndarray) -> np.ndarray:
        """Removed tets (n_tets,) of phi: the cut (half or more of the volume) or loose."""
        topo = self.topology(phi)
        return topo.removed | topo.loose

    def healthy_tets(self, phi: np.ndarray) -> np.ndarray:
        return ~self.removed(phi)

    def solve(self, pressure_pa: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        out, W = solve_with_cut(
            self.backend,
            pressure_pa=pressure_pa,
            level_set_m=phi,
            removed=self.removed(phi),
            warm_start=None,
            tissue=self.config.material,
            grads=self.assembler.geom.grads,
            tets=self.mesh.tets,
            grid=self.mesh.grid,
        )
        return out.u, W

    def advance(self, phi: np.ndarray, strain_energy: np.ndarray, step: int) -> np.ndarray:
        m = self.config.material
        if not cut_moves(strain_energy, m.damage_kappa_j_per_m3):
            return phi
        res = dissection_step(
            phi,
            strain_energy,
            self.removed(phi),
            mesh=self.mesh,
            grid=self.mesh.grid,
            volumes=self.assembler.geom.volumes,
            incidence=self.incidence,
            law=self.config.level_set.law(m.damage_kappa_j_per_m3),
            dt=self.config.dt_s,
            steps_since_reinit=self._steps_since_reinit,
            previous=self.topology(phi),
        )
        self._steps_since_reinit = res.steps_since_reinit
        self._topology = {res.level_set.tobytes(): res.topology}
        return res.level_set


def fem_physics(config: DatagenConfig) -> FemPhysics:
    """The default ``PhysicsFactory``: the engine's FEM mechanics and level set of ``config``."""
    mesh, assembler = _mesh_and_assembler(tuple(config.grid), tuple(config.block_m))
    return FemPhysics(mesh, assembler, config)
