"""The heat step's operator updated where rho c or k changed (``fem.edge_update``), bit for bit
``heat_operator.assemble_heat_operator``'s: a boiling node or a cut changes a few of a million
coefficients, and the weights, thetas, matrix entries and scaling they reach are recomputed alone.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from diathermy.errors import SceneError
from diathermy.fem.edge_update import EdgeIncidence, update_laplacian
from diathermy.physics.heat_operator import HeatMesh, HeatOperator, heat_operator_of


def updated_heat_operator(
    hmesh: HeatMesh,
    inc: EdgeIncidence,
    previous: HeatOperator,
    rho_c: np.ndarray,
    k: np.ndarray,
    changed_nodes: np.ndarray,
    changed_tets: np.ndarray,
    *,
    monotone: bool = True,
) -> HeatOperator:
    """``assemble_heat_operator`` of the same dt and Robin terms for rho_c (n_nodes,) and k
    (n_tets,), bit for bit, from ``previous``: rho_c changed on ``changed_nodes`` and k on
    ``changed_tets`` only (``inc``: the incidence of ``hmesh``'s stiffness and pattern), so only
    the weights, thetas and matrix entries that these reach are computed again."""
    stiff, dt_s, robin = hmesh.stiffness, previous.dt_s, previous.robin
    rc = np.asarray(rho_c, dtype=float)
    if not np.all(rc[changed_nodes] > 0) or not np.all(np.isfinite(rc[changed_nodes])):
        raise SceneError("volumetric heat capacity rho*c must be positive and finite at every node")
    kc = np.asarray(k, dtype=float)[changed_tets]
    if not np.all(kc > 0) or not np.all(np.isfinite(kc)):
        raise SceneError("thermal conductivity must be positive and finite in every tet")
    mass = rc * hmesh.nodal_volume
    w = previous.w
    k_edges = inc.edges_of_tets(changed_tets)
    if k_edges.size:
        w = w.copy()
        w[k_edges] = inc.weights_on(stiff, k, k_edges)
    # the nodes whose theta may change: new rho c, or a new weight at them
    nodes = np.union1d(changed_nodes, stiff.edges[k_edges].ravel())
    theta = previous.theta.copy()
    if monotone:
        with np.errstate(divide="ignore"):
            theta[nodes] = np.maximum(
                0.5, 1.0 - mass[nodes] / (dt_s * (inc.degree_on(w, nodes) + robin[nodes]))
            )
    edges = inc.incident_edges(nodes)  # their theta_ij, hence their theta_ij w_ij
    theta_edge = previous.theta_edge.copy()
    theta_edge[edges] = np.maximum(theta[stiff.edges[edges, 0]], theta[stiff.edges[edges, 1]])
    wt = theta_edge * w
    around = np.union1d(nodes, stiff.edges[edges].ravel())  # every diagonal that can change
    shift = mass[around] / dt_s + theta[around] * robin[around]
    up = update_laplacian(
        hmesh.pattern,
        inc,
        previous.matrix.data,
        previous.scaled.data,
        previous.scale,
        wt,
        edges,
        around,
        inc.degree_on(wt, around) + shift,
    )
    p = hmesh.pattern
    A = sp.csr_matrix((up.data, p.indices, p.indptr), shape=(p.n, p.n))
    off = previous.off_diagonal.copy()
    off[around] = inc.degree_on(np.abs(wt), around)
    scaled = sp.csr_matrix((up.scaled_data, p.indices, p.indptr), shape=(p.n, p.n))
    return heat_operator_of(dt_s, mass, robin, w, theta, theta_edge, A, scaled, up.scale, off)
