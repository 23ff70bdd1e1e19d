"""What every step of one simulation reads and never replaces: the scene, the discretization,
the solvers with their operator caches, the tissue laws, and the mechanics backend."""

from __future__ import annotations

from collections.abc import Callable
from functools import cached_property

import scipy.sparse as sp

from diathermy.engine.contact import ContactCache
from diathermy.engine.discretization import Discretization, build_discretization
from diathermy.fem.edges import edge_stiffness
from diathermy.physics.driven_potential import DrivenPotential
from diathermy.physics.electric import PotentialSolver
from diathermy.physics.electrothermal import ElectroThermal
from diathermy.physics.heat_operator import heat_mesh
from diathermy.physics.levelset import volume_incidence
from diathermy.physics.mechanics_backend import MechanicsBackend
from diathermy.physics.thermal import HeatStepper
from diathermy.physics.tissue_effects import ArrheniusDamage, ConductivityLaw
from diathermy.scene import Scene

POTENTIAL_STALE_FACTOR = 2.0
"""Keep the potential's AMG hierarchy until CG converges 2x slower per iteration than after its
build (benchmarks/results/realtime.md)..."""
POTENTIAL_MAX_STALE_SOLVES = 100
"""...and for at most this many solves with an outdated hierarchy."""


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
        self.working_region = scene.working_region()  # where the graded grid is fine
        stiffness = edge_stiffness(geom, mesh.tets, mesh.n_nodes)
        self.potential = DrivenPotential(
            # a cut or desiccation changes sigma on a few tets: the AMG hierarchy is kept while
            # it pays; checkpoints save the sigma it was built for, so restarts stay bitwise
            PotentialSolver(
                mesh,
                stiffness,
                rtol=scene.solver.electric_rtol,
                energy_tolerance=scene.solver.electric_energy_tolerance
                if scene.solver.incremental
                else None,
                window_m=scene.solver.electric_window_m if scene.solver.incremental else 0.0,
                stale_factor=POTENTIAL_STALE_FACTOR,
                max_stale_solves=POTENTIAL_MAX_STALE_SOLVES,
            )
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
            mesh,
            geom,
            stiffness=stiffness,
            potential=self.potential,
            heat=self.heat,
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

    @property
    def built_mechanics(self) -> MechanicsBackend | None:
        """The mechanics backend if it was built already (None: not yet used)."""
        return self._mechanics

    @cached_property
    def incidence(self) -> sp.csr_matrix:
        """Node-tet volume incidence of the mesh, built on the first cut."""
        return volume_incidence(self.disc.mesh.tets, self.disc.geom.volumes, self.disc.n_nodes)

    def has(self, effect: str) -> bool:
        """Whether the scene (closed over its dependencies) includes ``effect``."""
        return effect in self.effects
