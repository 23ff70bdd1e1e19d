"""The paper's strain-energy error (eq. 20/21) of a displacement field on a structured grid.

Glue for the surrogate evaluation (numpy only, so it lives outside ``surrogates``): builds the
Kuhn mesh of the dataset's grid once and calls the mechanics' one definition of W and of the
relative error, ``diathermy.physics.strain_energy``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from diathermy.fem.geometry import structured_geometry
from diathermy.mesh import Grid, TetMesh, build_tet_mesh
from diathermy.physics.materials import Tissue, ersatz_youngs_modulus
from diathermy.physics.strain_energy import relative_strain_energy_error, strain_energy_density
from diathermy.physics.topology import healthy_tets


def tet_youngs_modulus(level_set_m: np.ndarray, mesh: TetMesh, tissue: Tissue) -> np.ndarray:
    """E per tet (n_tets,) Pa: the tissue's on healthy tets (``topology.healthy_tets``), the
    ersatz modulus on removed ones, as the engine solves them."""
    healthy = healthy_tets(level_set_m.reshape(-1), mesh)
    return ersatz_youngs_modulus(healthy, tissue.youngs_modulus_pa, tissue.ersatz_stiffness_ratio)


def dataset_tissue(material: Mapping[str, Any] | None) -> Tissue:
    """The Tissue of a dataset's material record (unknown keys ignored, defaults for the rest)."""
    known = set(Tissue.__dataclass_fields__)
    return Tissue(**{k: v for k, v in (material or {}).items() if k in known})


def strain_energy_error_on_grid(
    grid_shape: tuple[int, int, int],
    spacing_m: tuple[float, float, float],
    material: Mapping[str, Any] | None = None,
) -> Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], float]:
    """fn(u (nz, ny, nx, 3) m, u_ref (same) m, pressure Pa, level set m) -> relative W error.

    ``spacing_m`` (dx, dy, dz); ``material`` the dataset's Tissue parameters (defaults for the
    rest). W uses E per tet from the reference level set, so both fields are weighed alike.
    """
    tissue = dataset_tissue(material)
    nz, ny, nx = grid_shape
    dx, dy, dz = spacing_m
    grid = Grid((nz, ny, nx), size_m=(dx * (nx - 1), dy * (ny - 1), dz * (nz - 1)))
    mesh = build_tet_mesh(grid)
    geom = structured_geometry(mesh.points, mesh.tets, mesh.shape_id)

    def error(
        u: np.ndarray, u_ref: np.ndarray, pressure: np.ndarray, level_set: np.ndarray
    ) -> float:
        del pressure  # W is of the total strain (PHYSICS.md section 2): no pressure term
        E = tet_youngs_modulus(np.asarray(level_set, float), mesh, tissue)
        nu = tissue.poisson_ratio
        W = strain_energy_density(geom.grads, mesh.tets, np.reshape(u, (-1, 3)), E, nu)
        W_ref = strain_energy_density(geom.grads, mesh.tets, np.reshape(u_ref, (-1, 3)), E, nu)
        return relative_strain_energy_error(W, W_ref)

    return error
