"""Everything derived from the grid alone, built once per simulation: mesh, geometry, patterns."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diathermy.fem.geometry import (
    ElementGeometry,
    nodal_volumes,
    structured_geometry,
)
from diathermy.fem.sparsity import Pattern, build_pattern
from diathermy.mesh import SIDES, Grid, TetMesh, build_tet_mesh


@dataclass(frozen=True)
class Discretization:
    """The mesh of a scene's grid and the per-mesh data every solver reuses."""

    grid: Grid
    mesh: TetMesh
    geom: ElementGeometry
    pattern: Pattern
    node_volumes_m3: np.ndarray  # (n_nodes,)
    outer_faces: np.ndarray  # (n_faces, 3) all six sides, convective boundary
    bottom_nodes: np.ndarray  # grounded (V = 0) and clamped (u = 0)

    @property
    def n_nodes(self) -> int:
        return self.mesh.n_nodes

    @property
    def n_tets(self) -> int:
        return self.mesh.n_tets

    def to_grid(self, nodal: np.ndarray) -> np.ndarray:
        """Nodal (n_nodes,) or (n_nodes, 3) -> grid-shaped (nz, ny, nx[, 3])."""
        return nodal.reshape(self.grid.shape + nodal.shape[1:])


def build_discretization(grid: Grid) -> Discretization:
    """Mesh and reusable geometry of a grid (uniform or graded)."""
    mesh = build_tet_mesh(grid)
    geom = structured_geometry(mesh.points, mesh.tets, mesh.shape_id)
    return Discretization(
        grid=grid,
        mesh=mesh,
        geom=geom,
        pattern=build_pattern(mesh.tets, mesh.n_nodes),
        node_volumes_m3=nodal_volumes(geom, mesh.tets, mesh.n_nodes),
        outer_faces=np.concatenate([mesh.boundary_faces[s] for s in SIDES]),
        bottom_nodes=mesh.side_nodes("z-"),
    )
