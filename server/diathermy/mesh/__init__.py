"""Structured grids of nodes (uniform or graded) and their conforming 6-tetrahedra-per-cell meshes."""

from diathermy.mesh.grid import Grid
from diathermy.mesh.grid_attrs import grid_attrs, grid_from_attrs
from diathermy.mesh.tet_mesh import SIDES, TetMesh, barycentric, build_tet_mesh

__all__ = [
    "SIDES",
    "Grid",
    "TetMesh",
    "barycentric",
    "build_tet_mesh",
    "grid_attrs",
    "grid_from_attrs",
]
