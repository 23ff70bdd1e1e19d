"""Scalar P1 kernels: diffusion, consistent and lumped mass, Robin terms, volume and surface loads.

Coefficients are per tet (diffusion, mass) or per boundary triangle (Robin, flux), passed as
arrays; every kernel returns a plain sparse matrix or vector.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from diathermy.fem.geometry import ElementGeometry
from diathermy.fem.sparsity import Pattern

_P1_MASS = (np.ones((4, 4)) + np.eye(4)) / 20.0  # int_T N_a N_b / |T|
_TRI_MASS = (np.ones((3, 3)) + np.eye(3)) / 12.0  # int_F N_a N_b / |F|


def diffusion_local(geom: ElementGeometry, coeff: np.ndarray) -> np.ndarray:
    """Element matrices (n_tets, 4, 4): coeff_e |T_e| grad N_a . grad N_b."""
    w = np.asarray(coeff, dtype=float) * geom.volumes
    return np.einsum("e,eak,ebk->eab", w, geom.grads, geom.grads)


def assemble_diffusion(pattern: Pattern, geom: ElementGeometry, coeff: np.ndarray) -> sp.csr_matrix:
    """Stiffness matrix of -div(coeff grad u) with a per-tet coefficient (n_tets,)."""
    return pattern.csr(diffusion_local(geom, np.broadcast_to(coeff, geom.volumes.shape)))


def assemble_mass(
    pattern: Pattern, geom: ElementGeometry, coeff: np.ndarray | float = 1.0
) -> sp.csr_matrix:
    """Consistent mass matrix int coeff N_a N_b with a per-tet coefficient."""
    w = np.broadcast_to(np.asarray(coeff, dtype=float), geom.volumes.shape) * geom.volumes
    return pattern.csr(w[:, None, None] * _P1_MASS[None])


def lumped_mass(
    geom: ElementGeometry, tets: np.ndarray, n_nodes: int, coeff: np.ndarray | float = 1.0
) -> np.ndarray:
    """Row-sum lumped mass (n_nodes,): sum over adjacent tets of coeff_e |T_e| / 4."""
    w = np.broadcast_to(np.asarray(coeff, dtype=float), geom.volumes.shape) * geom.volumes / 4.0
    return np.bincount(tets.ravel(), np.repeat(w, 4), minlength=n_nodes)


def triangle_areas(points: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Areas (n,) in m^2 of triangles (n, 3)."""
    v = points[tris]
    return 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)


def assemble_robin(
    points: np.ndarray,
    tris: np.ndarray,
    n_nodes: int,
    h: np.ndarray | float,
    *,
    lumped: bool = True,
) -> sp.csr_matrix:
    """Boundary matrix int_F h N_a N_b over triangles (lumped to the diagonal by default)."""
    w = np.broadcast_to(np.asarray(h, dtype=float), (tris.shape[0],)) * triangle_areas(points, tris)
    if lumped:
        diag = np.bincount(tris.ravel(), np.repeat(w / 3.0, 3), minlength=n_nodes)
        return sp.diags(diag, format="csr")
    local = w[:, None, None] * _TRI_MASS[None]
    rows = np.repeat(tris, 3, axis=1).ravel()
    cols = np.tile(tris, (1, 3)).ravel()
    return sp.csr_matrix((local.ravel(), (rows, cols)), shape=(n_nodes, n_nodes))


def surface_load(
    points: np.ndarray, tris: np.ndarray, n_nodes: int, flux: np.ndarray | float
) -> np.ndarray:
    """Nodal load (n_nodes,) of a per-triangle constant flux: int_F flux N_a = flux |F| / 3."""
    w = np.broadcast_to(np.asarray(flux, dtype=float), (tris.shape[0],)) * triangle_areas(
        points, tris
    )
    return np.bincount(tris.ravel(), np.repeat(w / 3.0, 3), minlength=n_nodes)


def volume_load_matrix(geom: ElementGeometry, tets: np.ndarray, n_nodes: int) -> sp.csr_matrix:
    """The nodal load of a per-tet constant source as a matrix (n_nodes, n_tets):
    int_T q N_a = q |T| / 4, so ``M @ q`` is ``volume_load``; reused, one product costs about a
    third of the bincount."""
    n_t = tets.shape[0]
    by_tet = sp.csr_matrix(
        (np.repeat(geom.volumes / 4.0, 4), tets.ravel(), 4 * np.arange(n_t + 1)),
        shape=(n_t, n_nodes),
    )
    return by_tet.T.tocsr()


def volume_load(geom: ElementGeometry, tets: np.ndarray, n_nodes: int, q: np.ndarray) -> np.ndarray:
    """Nodal load (n_nodes,) of a per-tet constant source q (n_tets,) (``volume_load_matrix``)."""
    return volume_load_matrix(geom, tets, n_nodes) @ np.asarray(q, dtype=float)
