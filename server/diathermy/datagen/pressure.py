"""Tet (Gauss-point) pressures to the nodal pressure field the solver and the CNN take.

Algorithm 1 assigns pressures to tet Gauss points (centroids). The nodal field is
p_n = p0 + sum_t V_t (p_t - p0) / sum_t V_t over the tets t around node n, unvisited tets
sitting at p0: a volume-weighted mean of the excess pressure, so p0 stays exactly p0 away from
the walk and every nodal value lies within the range of its tets. The mean is the level set's
``tet_to_node`` (the lumped-mass L2 projection onto P1), the one place of that projection.
"""

from __future__ import annotations

import numpy as np

from diathermy.physics.levelset import tet_to_node


def nodal_pressure(
    tets: np.ndarray, volumes_m3: np.ndarray, p_tet_pa: np.ndarray, p0_pa: float, n_nodes: int
) -> np.ndarray:
    """Nodal pressure (n_nodes,) in Pa from tets (n_tets, 4), volumes (n_tets,), p_tet (n_tets,)."""
    return p0_pa + tet_to_node(p_tet_pa - p0_pa, tets, volumes_m3, n_nodes)
