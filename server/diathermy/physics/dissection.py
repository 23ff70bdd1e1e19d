"""One dissection step (PHYSICS.md section 4): the cut front moves where the strain energy passes
kappa, the level set is re-initialised on its schedule, and the topology follows.

The one implementation of this step: the engine's dissection effect and the dataset generator
(Algorithm 1) both call ``dissection_step``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from diathermy.mesh import Grid, TetMesh
from diathermy.physics.levelset import (
    advance,
    front_speed,
    grid_spacing,
    reinitialize,
    tet_to_node,
)
from diathermy.physics.levelset_law import LevelSetLaw
from diathermy.physics.topology import Topology, evaluate_topology


@dataclass(frozen=True)
class DissectionStep:
    """What one step did: the new level set (n_nodes,) in m, its topology, the removed mask
    (cut or loose, n_tets), whether it re-initialised, the re-init counter after the step, and
    the sub-steps and active nodes of the front advance."""

    level_set: np.ndarray
    topology: Topology
    removed: np.ndarray
    reinitialized: bool
    steps_since_reinit: int
    n_substeps: int
    n_active: int


def cut_moves(strain_energy: np.ndarray, kappa_j_per_m3: float) -> bool:
    """Whether any tet's strain energy (J/m^3) passes kappa, i.e. the front can move at all."""
    return bool(strain_energy.max() > kappa_j_per_m3)


def dissection_step(
    level_set: np.ndarray,
    strain_energy: np.ndarray,
    removed: np.ndarray,
    *,
    mesh: TetMesh,
    grid: Grid,
    volumes: np.ndarray,
    incidence: sp.csr_matrix,
    law: LevelSetLaw,
    dt: float,
    steps_since_reinit: int,
    previous: Topology | None,
) -> DissectionStep:
    """Advance the cut one step dt (s) under the strain energy per tet (J/m^3).

    Removed tets carry ~0 W: they are left out of the nodal average so that they do not dilute
    W on the cut surface. ``previous`` is the last topology (its loose fragments are reused when
    the removed mask is unchanged).
    """
    W_nodes = tet_to_node(
        strain_energy, mesh.tets, volumes, mesh.n_nodes, include=~removed, incidence=incidence
    )
    F = front_speed(W_nodes, law.kappa_j_per_m3, law.v0_m_per_s)
    adv = advance(level_set.reshape(grid.shape), F, grid_spacing(grid), dt, cfl=law.cfl)
    new_phi = adv.phi
    steps_since_reinit += 1
    reinit = steps_since_reinit >= law.reinit_every
    if reinit:
        # keeps every node's sign and never raises phi next to the front (see reinitialize)
        new_phi = reinitialize(new_phi, grid_spacing(grid))
        steps_since_reinit = 0
    phi = new_phi.ravel()
    topo = evaluate_topology(phi, mesh, volumes, previous)
    return DissectionStep(
        level_set=phi,
        topology=topo,
        removed=topo.removed | topo.loose,
        reinitialized=reinit,
        steps_since_reinit=steps_since_reinit,
        n_substeps=adv.n_substeps,
        n_active=adv.n_active,
    )
