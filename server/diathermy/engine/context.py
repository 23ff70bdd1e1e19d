"""What every step of one simulation reads and never replaces: the scene, the discretization,
the solvers with their operator caches, the tissue laws, and the mechanics backend."""

from __future__ import annotations

from collections.abc import Callable
from functools import cached_property

import scipy.sparse as sp

from diathermy.engine.contact import ContactCache
from diathermy.engine.discretization import Discretization, build_discretization
from diathermy.fem.edges import edge_stiffness
from diathermy.physics.electric import DrivenPotential, PotentialSolver
from diathermy.physics.electrothermal import ElectroThermal
from diathermy.physics.heat_operator import heat_mesh
from diathermy.physics.levelset import volume_incidence
from diathermy.physics.mechanics_backend import MechanicsBackend
from diathermy.physics.thermal import HeatStepper
from diathermy.physics.tissue_effects import ArrheniusDamage, ConductivityLaw
from diathermy.scene import Scene


class EngineContext:
    """The fixed part of a simulation of ``scene``; ``mechanics_factory`` builds the mechanics
    backend on first use (a surrogate backend loads its model there)."""

    def __init__(
        self, scene: Scene, mechanics_factory: Callable[[EngineContext], MechanicsBackend]
    ) -> None:
        self.scene = scene
        self.tissue = scene.material
        self.effects: tuple[str, ...] = scene.closed_effects
        self.disc: Discretization = build_discretization(scene.node_grid())
        mesh, geom = self.disc.mesh, self.disc.geom
        self.top_z = float(self.disc.grid.origin_m[2] + self.disc.grid.size_m[2])
        stiffness = edge_stiffness(geom, mesh.tets, mesh.n_nodes)
        self.potential = DrivenPotential(
            # hierarchies rebuilt from the current operator: a restored run repeats the original
            PotentialSolver(mesh, stiffness, rtol=scene.solver.electric_rtol, stale_factor=0.0)
        )
        self.heat = HeatStepper(
            heat_mesh(mesh, geom, stiffness),
            h_w_per_m2_k=self.tissue.h_convective_w_per_m2_k,
            t_ambient_k=self.tissue.t_ambient_k,
            rtol=scene.solver.thermal_rtol,
            amg_stale_factor=0.0,  # rebuild from the current operator: restarts stay bitwise
        )
        # the paper's monolithic option shares the potential and heat solvers above
        self.coupled = ElectroThermal(
            mesh, geom, stiffness=stiffness, potential=self.potential, heat=self.heat
        )
        self.conductivity_law = ConductivityLaw()
        self.damage_law = ArrheniusDamage()
        self.contacts = ContactCache()
        self._mechanics_factory = mechanics_factory
        self._mechanics: MechanicsBackend | None = None

    @property
    def mechanics(self) -> MechanicsBackend:
        """The mechanics backend, built on first use."""
        if self._mechanics is None:
            self._mechanics = self._mechanics_factory(self)
        return self._mechanics

    @mechanics.setter
    def mechanics(self, backend: MechanicsBackend) -> None:
        self._mechanics = backend

    @cached_property
    def incidence(self) -> sp.csr_matrix:
        """Node-tet volume incidence of the mesh, built on the first cut."""
        return volume_incidence(self.disc.mesh.tets, self.disc.geom.volumes, self.disc.n_nodes)

    def has(self, effect: str) -> bool:
        """Whether the scene (closed over its dependencies) includes ``effect``."""
        return effect in self.effects
