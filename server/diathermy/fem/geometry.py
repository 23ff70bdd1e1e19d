"""Per-element geometry of linear tetrahedra: shape-function gradients and volumes."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ElementGeometry:
    """Gradients (n_tets, 4, 3) of the 4 barycentric shape functions in 1/m, volumes (n_tets,) in m^3."""

    grads: np.ndarray
    volumes: np.ndarray


def element_geometry(points: np.ndarray, tets: np.ndarray) -> ElementGeometry:
    """Shape-function gradients and volumes of every tet (vectorised, no element loop)."""
    v = points[tets]  # (n, 4, 3)
    J = np.swapaxes(v[:, 1:, :] - v[:, :1, :], 1, 2)  # (n, 3, 3), columns v_i - v_0
    det = np.linalg.det(J)
    Jinv = np.linalg.inv(J)  # rows are the gradients of lambda_1..3
    grads = np.empty((tets.shape[0], 4, 3))
    grads[:, 1:, :] = Jinv
    grads[:, 0, :] = -Jinv.sum(axis=1)
    return ElementGeometry(grads=grads, volumes=det / 6.0)


def gradient(geom: ElementGeometry, tets: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Element-wise gradient (n_tets, 3) of a nodal P1 field u (n_nodes,)."""
    return np.einsum("ea,eak->ek", u[tets], geom.grads)


def nodal_volumes(geom: ElementGeometry, tets: np.ndarray, n_nodes: int) -> np.ndarray:
    """Lumped (row-sum) nodal volume (n_nodes,) in m^3: a quarter of each adjacent tet."""
    return np.bincount(tets.ravel(), np.repeat(geom.volumes / 4.0, 4), minlength=n_nodes)


def kuhn_boxes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Cell size (n_tets, 3) as (hx, hy, hz) in m of each Kuhn tet's hexahedral cell.

    Vertex 0 of a Kuhn tet is the cell's corner 000 and the far corner 111 is vertex 2 or 3
    (``mesh.tet_mesh.kuhn_corners``), so the cell is their componentwise largest offset.
    """
    p0 = points[tets[:, 0]]
    return np.maximum(points[tets[:, 2]] - p0, points[tets[:, 3]] - p0)


def structured_geometry(
    points: np.ndarray, tets: np.ndarray, shape_id: np.ndarray
) -> ElementGeometry:
    """Geometry of a Kuhn mesh (uniform or graded) without per-tet 3x3 inverses.

    Uniform grid: every tet is a translate of one of 6 reference tets; their geometry is
    computed once and gathered by ``shape_id`` (n_tets,). Graded grid: a Kuhn tet of a cell
    (hx, hy, hz) is the unit-cube tet scaled per axis, so its gradients are the unit ones
    (entries 0, +-1) divided by (hx, hy, hz) and its volume hx hy hz / 6. Equal to
    ``element_geometry`` on such meshes, several times faster on large grids.
    """
    first = np.array([np.flatnonzero(shape_id == s)[0] for s in range(6)])
    sid = shape_id.astype(np.intp)
    ref = element_geometry(points, tets[first])
    one_per_cell = tets[shape_id == 0]  # every cell has one tet of each shape
    cells = kuhn_boxes(points, one_per_cell)
    ref_box = kuhn_boxes(points, tets[first])
    if np.all(np.abs(cells - ref_box[0]) <= 1e-9 * ref_box[0]):  # uniform grid
        return ElementGeometry(grads=ref.grads[sid], volumes=ref.volumes[sid])
    box = kuhn_boxes(points, tets)
    unit = np.rint(ref.grads * ref_box[:, None, :])  # (6, 4, 3) gradients on the unit cube
    return ElementGeometry(grads=unit[sid] / box[:, None, :], volumes=box.prod(axis=1) / 6.0)
