"""The electrode's contact disk as a nodal load: an exact quadrature of the disk spread over
the tets it crosses (PHYSICS.md section 2), so the injected current is j * area at every
resolution, also when the disk is smaller than a cell."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diathermy.errors import SceneError
from diathermy.mesh import TetMesh


@dataclass(frozen=True)
class ContactWeights:
    """The electrode's contact disk as a nodal load per unit current density.

    Attributes:
        weights: int over the disk of each shape function (n_nodes,) in m^2.
        area_m2: disk area inside the block (= weights.sum()), in m^2.
    """

    weights: np.ndarray
    area_m2: float


def disk_quadrature(
    center_m: np.ndarray, radius_m: float, n_radial: int, n_angular: int
) -> tuple[np.ndarray, np.ndarray]:
    """Points (n, 3) and weights (n,) in m^2 of a horizontal disk; weights sum to pi a^2.

    Gauss-Legendre in r (exact for the r dr measure) times equispaced angles.
    """
    s, ws = np.polynomial.legendre.leggauss(n_radial)
    r = 0.5 * radius_m * (s + 1.0)
    wr = 0.5 * radius_m * ws * r  # int_0^a f(r) r dr
    phi = (np.arange(n_angular) + 0.5) * (2.0 * np.pi / n_angular)
    rr, pp = np.meshgrid(r, phi, indexing="ij")
    pts = np.column_stack(
        [
            center_m[0] + (rr * np.cos(pp)).ravel(),
            center_m[1] + (rr * np.sin(pp)).ravel(),
            np.full(rr.size, center_m[2]),
        ]
    )
    w = np.repeat(wr * (2.0 * np.pi / n_angular), n_angular)
    return pts, w


N_RADIAL = 16
"""Gauss-Legendre points of the contact disk's quadrature in r."""
N_ANGULAR = 64
"""Equispaced angles of the contact disk's quadrature."""


def contact_weights(
    mesh: TetMesh,
    center_m: tuple[float, float, float] | np.ndarray,
    radius_m: float,
    *,
    heights_m: np.ndarray | None = None,
    n_radial: int = N_RADIAL,
    n_angular: int = N_ANGULAR,
) -> ContactWeights:
    """Nodal weights of a contact disk of radius a centred at center_m = (x, y, z), in m.

    ``heights_m`` (one z per quadrature point of ``disk_quadrature``, in m) drapes the disk
    over a surface: each point keeps its (x, y) and its weight (the projected area) but sits
    at its own height; points with a NaN height are dropped (no tissue under them). Quadrature
    points outside the block are dropped (an electrode over an edge loses that part of its
    area); the others are spread over their tet's vertices by barycentric coordinates.
    """
    center = np.asarray(center_m, dtype=float)
    if center.shape != (3,) or not np.all(np.isfinite(center)):
        raise SceneError(f"electrode centre must be 3 finite coordinates in m, got {center_m}")
    if not radius_m > 0:
        raise SceneError(f"electrode contact radius must be positive, got {radius_m}")
    pts, w = disk_quadrature(center, radius_m, n_radial, n_angular)
    if heights_m is not None:
        z = np.asarray(heights_m, dtype=float)
        if z.shape != (pts.shape[0],):
            raise SceneError(f"draped contact needs {pts.shape[0]} heights, got shape {z.shape}")
        keep = np.isfinite(z)
        pts, w = pts[keep], w[keep]
        pts[:, 2] = z[keep]
    inside = mesh.grid.contains(pts)
    pts, w = pts[inside], w[inside]
    if w.size == 0:
        raise SceneError(f"electrode contact disk at {center.tolist()} lies outside the block")
    tet, lam = mesh.locate(pts)
    weights = np.bincount(
        mesh.tets[tet].ravel(), (lam * w[:, None]).ravel(), minlength=mesh.n_nodes
    )
    return ContactWeights(weights=weights, area_m2=float(weights.sum()))


def same_contact(a: ContactWeights, b: ContactWeights | None) -> bool:
    """Whether ``b`` is the same contact load as ``a`` (identical weights)."""
    return b is not None and (a is b or np.array_equal(a.weights, b.weights))
