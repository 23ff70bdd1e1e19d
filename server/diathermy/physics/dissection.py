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
from diathermy.physics.nonlocal_average import axis_kernels, nonlocal_mean
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


def cut_driver(
    strain_energy: np.ndarray,
    removed: np.ndarray,
    *,
    mesh: TetMesh,
    grid: Grid,
    volumes: np.ndarray,
    incidence: sp.csr_matrix | None,
    length_m: float,
    tissue_share: np.ndarray | None = None,
) -> np.ndarray:
    """The nodal strain energy (n_nodes,) in J/m^3 that drives the front: the volume-weighted
    mean over the healthy tets around each node, averaged over the material length ``length_m``
    (m) when it is positive (``nonlocal_average``), else the local mean itself.

    Removed tets carry ~0 W: they are left out so that they do not dilute W on the cut surface.
    ``tissue_share`` (n_tets,) in [0, 1] ('fraction' removal) weights each tet by the tissue left
    in it instead.
    """
    include = ~np.asarray(removed, dtype=bool) if tissue_share is None else tissue_share
    W_nodes = tet_to_node(
        strain_energy, mesh.tets, volumes, mesh.n_nodes, include=include, incidence=incidence
    )
    if length_m <= 0.0:
        return W_nodes
    if incidence is None:
        weights = np.bincount(mesh.tets.reshape(-1), np.repeat(volumes * include, 4), mesh.n_nodes)
    else:
        weights = incidence @ include.astype(float)
    return nonlocal_mean(W_nodes, weights, grid.shape, axis_kernels(grid.axes(), length_m))


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
    tissue_share: np.ndarray | None = None,
) -> DissectionStep:
    """Advance the cut one step dt (s) under the strain energy per tet (J/m^3).

    The front is driven by ``cut_driver`` (the law's non-local length). ``previous`` is the
    last topology (its loose fragments are reused when the removed mask is unchanged);
    ``tissue_share``: see ``cut_driver``.
    """
    W_nodes = cut_driver(
        strain_energy,
        removed,
        mesh=mesh,
        grid=grid,
        volumes=volumes,
        incidence=incidence,
        length_m=law.nonlocal_length_m,
        tissue_share=tissue_share,
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
