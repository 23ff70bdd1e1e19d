"""Mechanics backends behind one interface (FEM here; the CNN and PGD surrogates implement it too).

It sits below the engine so that the surrogates can implement it without importing the engine.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from diathermy.fem.elastic import ElasticAssembler
from diathermy.mesh import TetMesh
from diathermy.physics.materials import Tissue, ersatz_youngs_modulus
from diathermy.physics.mechanics import MechanicsSolver, mechanics_assembler
from diathermy.physics.strain_energy import strain_energy_density


@dataclass(frozen=True)
class MechanicsOutput:
    """A backend's answer: nodal displacement (n_nodes, 3) in m, plus what it cost."""

    u: np.ndarray
    iterations: int = 0
    residual: float = 0.0
    rebuilt: bool = False
    loose_tets: np.ndarray | None = None  # tets a solver decided to remove (loose fragments)
    extra: dict[str, Any] = field(default_factory=dict)


class MechanicsBackend(Protocol):
    """Solves the mechanics of one step: (pressure, level set, topology) -> displacement."""

    name: str

    def solve(
        self,
        *,
        pressure_pa: np.ndarray,
        level_set_m: np.ndarray,
        youngs_modulus_pa: np.ndarray,
        healthy: np.ndarray,
        warm_start: np.ndarray | None,
    ) -> MechanicsOutput: ...


class FEMBackend:
    """The high-fidelity elastostatic FEM solve; the operator is rebuilt only when E changes."""

    name = "fem"

    def __init__(
        self,
        mesh: TetMesh,
        *,
        poisson_ratio: float,
        p0_pa: float,
        rtol: float,
        ersatz_ratio: float,
        assembler: ElasticAssembler | None = None,
    ) -> None:
        self.mesh = mesh
        self.poisson_ratio = poisson_ratio
        self.p0_pa = p0_pa
        self.rtol = rtol
        self.ersatz_ratio = ersatz_ratio
        self._assembler = assembler
        self._solver: MechanicsSolver | None = None
        self._E: np.ndarray | None = None
        self.n_builds = 0
        self.n_solves = 0

    @property
    def solver(self) -> MechanicsSolver | None:
        return self._solver

    @property
    def assembler(self) -> ElasticAssembler:
        """The mesh's elasticity assembler, built on first use and shared by every topology."""
        if self._assembler is None:
            self._assembler = mechanics_assembler(self.mesh)
        return self._assembler

    def operator_for(
        self, youngs_modulus_pa: np.ndarray, healthy: np.ndarray
    ) -> tuple[MechanicsSolver, bool]:
        """The solver of this topology, rebuilt only if E changed; (solver, rebuilt)."""
        if (
            self._solver is not None
            and self._E is not None
            and np.array_equal(self._E, youngs_modulus_pa)
        ):
            return self._solver, False
        self._solver = MechanicsSolver(
            self.mesh,
            youngs_modulus_pa,
            self.poisson_ratio,
            healthy=healthy,
            ersatz_ratio=self.ersatz_ratio,
            rtol=self.rtol,
            assembler=self.assembler,
        )
        self._E = youngs_modulus_pa.copy()
        self.n_builds += 1
        return self._solver, True

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
        solver, rebuilt = self.operator_for(youngs_modulus_pa, healthy)
        build_s = time.perf_counter() - t0
        res = solver.solve(pressure_pa, self.p0_pa, x0=warm_start)
        self.n_solves += 1
        loose = solver.fragments.loose
        return MechanicsOutput(
            u=res.u,
            iterations=res.stats.iterations,
            residual=res.stats.residual,
            rebuilt=rebuilt,
            loose_tets=loose if loose.any() else None,
            extra={
                "operator_s": build_s,
                "amg_setup_s": res.stats.amg_setup_s,
                "solve_s": res.stats.solve_s,
            },
        )


def solve_with_cut(
    backend: MechanicsBackend,
    *,
    pressure_pa: np.ndarray,
    level_set_m: np.ndarray,
    removed: np.ndarray,
    warm_start: np.ndarray | None,
    tissue: Tissue,
    grads: np.ndarray,
    tets: np.ndarray,
) -> tuple[MechanicsOutput, np.ndarray]:
    """Displacement under the pore pressure (Pa) with the cut as ersatz material, and the strain
    energy density per tet (J/m^3) of the stiffness it was solved with (a loose fragment is
    ersatz too). The one mechanics step of the engine and the dataset generator."""
    E = ersatz_youngs_modulus(~removed, tissue.youngs_modulus_pa, tissue.ersatz_stiffness_ratio)
    out = backend.solve(
        pressure_pa=pressure_pa,
        level_set_m=level_set_m,
        youngs_modulus_pa=E,
        healthy=~removed,
        warm_start=warm_start,
    )
    E_eff = E.copy()
    if out.loose_tets is not None:
        E_eff[out.loose_tets] = tissue.ersatz_stiffness_ratio * tissue.youngs_modulus_pa
    W = strain_energy_density(grads, tets, out.u, E_eff, tissue.poisson_ratio)
    return out, W
