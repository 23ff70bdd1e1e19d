"""Mechanics backends behind one interface (FEM here; the CNN and PGD surrogates implement it too).

It sits below the engine so that the surrogates can implement it without importing the engine.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from diathermy.fem.elastic import ElasticAssembler
from diathermy.fem.solvers import KrylovSolver, ReuseState
from diathermy.mesh import TetMesh
from diathermy.mesh.grid import Grid
from diathermy.physics.materials import Tissue, ersatz_youngs_modulus
from diathermy.physics.mechanics import DEFAULT_AMG_OPTIONS, MechanicsSolver, mechanics_assembler
from diathermy.physics.strain_energy import kuhn_strain_energy_density, strain_energy_density

MECHANICS_STALE_FACTOR = 2.0
"""Keep the AMG hierarchy of an earlier topology until CG converges 2x slower per iteration
than right after its build (benchmarks/results/realtime.md: a cut of a few tets per step)."""
MECHANICS_MAX_STALE_SOLVES = 100
"""...and rebuild it after at most this many solves with an outdated hierarchy."""


@dataclass(frozen=True)
class Rescaled:
    """u = alpha x the warm start on every node but ``nodes``; ``previous_E_pa`` (n_tets,) is the
    E per tet (loose fragments ersatz) of the solve that gave the warm start."""

    alpha: float
    nodes: np.ndarray
    previous_E_pa: np.ndarray


@dataclass(frozen=True)
class MechanicsOutput:
    """A backend's answer: nodal displacement (n_nodes, 3) in m, plus what it cost."""

    u: np.ndarray
    iterations: int = 0
    residual: float = 0.0
    rebuilt: bool = False
    loose_tets: np.ndarray | None = None  # tets a solver decided to remove (loose fragments)
    rescaled: Rescaled | None = None  # set when u is the warm start rescaled but for a few nodes
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


@dataclass(frozen=True)
class HierarchyOrigin:
    """The topology the mechanics AMG hierarchy was built for: E per tet (Pa) and the healthy
    mask of that solve (loose fragments removed; the tissue shares under 'fraction' removal),
    with the reuse counters since; a checkpoint saves it so that a restored run rebuilds the
    very same preconditioner."""

    youngs_modulus_pa: np.ndarray
    healthy: np.ndarray
    reuse: ReuseState


class FEMBackend:
    """The high-fidelity elastostatic FEM solve; the operator is rebuilt only when E changes, and
    its AMG hierarchy is kept across topologies while it pays (``stale_factor``, 0: rebuild
    with every new E)."""

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
        stale_factor: float = MECHANICS_STALE_FACTOR,
        max_stale_solves: int = MECHANICS_MAX_STALE_SOLVES,
    ) -> None:
        self.mesh = mesh
        self.poisson_ratio = poisson_ratio
        self.p0_pa = p0_pa
        self.rtol = rtol
        self.ersatz_ratio = ersatz_ratio
        self._assembler = assembler
        self._solver: MechanicsSolver | None = None
        self._E: np.ndarray | None = None
        self._krylov = KrylovSolver(
            "elasticity",
            rtol=rtol,
            maxiter=500,
            amg_options=DEFAULT_AMG_OPTIONS,
            stale_factor=stale_factor,
            max_stale_solves=max_stale_solves,
            refresh_coarse=True,
        )
        self._origin: tuple[np.ndarray, np.ndarray] | None = None
        self.n_builds = 0
        self.n_solves = 0

    @property
    def hierarchy_origin(self) -> HierarchyOrigin | None:
        """Where the current AMG hierarchy comes from (None before the first solve)."""
        if self._origin is None:
            return None
        return HierarchyOrigin(*self._origin, reuse=self._krylov.reuse)

    def restore_hierarchy(self, origin: HierarchyOrigin) -> None:
        """Rebuild the hierarchy of ``origin`` (as saved by a checkpoint) and its counters; the
        next solve then keeps or rebuilds it exactly as the original run did."""
        solver, _ = self.operator_for(origin.youngs_modulus_pa, origin.healthy)
        self._krylov.build()
        self._krylov.reuse = origin.reuse
        self._origin = (solver.youngs_modulus_pa.copy(), solver.load_weight.copy())

    @property
    def krylov(self) -> KrylovSolver:
        """The CG solver shared by every topology (its hierarchy and reuse counters)."""
        return self._krylov

    @property
    def solver(self) -> MechanicsSolver | None:
        return self._solver

    @property
    def assembler(self) -> ElasticAssembler:
        """The mesh's elasticity assembler, built on first use and shared by every topology."""
        if self._assembler is None:
            self._assembler = mechanics_assembler(self.mesh)
        return self._assembler

    def fresh_operator(
        self, youngs_modulus_pa: np.ndarray, healthy: np.ndarray, **kw: Any
    ) -> MechanicsSolver:
        """A solver of this mesh for E (n_tets,) Pa and ``healthy``; by default with its own CG
        solver, so the backend's kept operator and hierarchy are not touched (``kw``: the
        solver's ``krylov``, ``base`` and ``consume_base``)."""
        return MechanicsSolver(
            self.mesh,
            youngs_modulus_pa,
            self.poisson_ratio,
            healthy=healthy,
            ersatz_ratio=self.ersatz_ratio,
            rtol=self.rtol,
            assembler=self.assembler,
            **kw,
        )

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
        base, self._solver = self._solver, None  # a failed build must not leave it consumed
        self._solver = self.fresh_operator(
            youngs_modulus_pa, healthy, krylov=self._krylov, base=base, consume_base=True
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
        if res.stats.rebuilt:
            self._origin = (solver.youngs_modulus_pa.copy(), solver.load_weight.copy())
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
                "amg_stale": res.stats.stale,
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
    previous_W: np.ndarray | None = None,
    grid: Grid | None = None,
    tissue_share: np.ndarray | None = None,
) -> tuple[MechanicsOutput, np.ndarray]:
    """Displacement under the pore pressure (Pa) with the cut as ersatz material, and the strain
    energy density per tet (J/m^3) of the stiffness it was solved with (a loose fragment is
    ersatz too). The one mechanics step of the engine and the dataset generator.

    ``previous_W`` (n_tets,) is the strain energy of the warm start: when the backend says u is
    alpha x the warm start but on a few nodes (``MechanicsOutput.rescaled``), W is alpha^2 x it
    except on the tets of those nodes and the tets whose E changed, which are recomputed.
    ``grid``: the grid whose Kuhn mesh ``tets`` is, for a faster W of the whole mesh.
    ``tissue_share``: each tet's share (n_tets,) in [0, 1] still tissue (``level_set.removal``
    'fraction'): E and the pore pressure's load are blended by it instead of switched by
    ``removed``."""
    healthy = ~removed if tissue_share is None else tissue_share
    E = ersatz_youngs_modulus(healthy, tissue.youngs_modulus_pa, tissue.ersatz_stiffness_ratio)
    out = backend.solve(
        pressure_pa=pressure_pa,
        level_set_m=level_set_m,
        youngs_modulus_pa=E,
        healthy=healthy,
        warm_start=warm_start,
    )
    E_eff = E.copy()
    if out.loose_tets is not None:
        E_eff[out.loose_tets] = tissue.ersatz_stiffness_ratio * tissue.youngs_modulus_pa
    r = out.rescaled
    if r is None or previous_W is None:
        if grid is not None:
            return out, kuhn_strain_energy_density(out.u, grid, E_eff, tissue.poisson_ratio)
        return out, strain_energy_density(grads, tets, out.u, E_eff, tissue.poisson_ratio)
    moved = np.zeros(out.u.shape[0], dtype=bool)
    moved[r.nodes] = True
    redo = np.flatnonzero(moved[tets].any(axis=1) | (E_eff != r.previous_E_pa))
    W = (r.alpha * r.alpha) * previous_W
    W[redo] = strain_energy_density(
        grads[redo], tets[redo], out.u, E_eff[redo], tissue.poisson_ratio
    )
    return out, W
