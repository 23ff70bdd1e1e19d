"""Tet (Gauss-point) pressures to the nodal pressure field the solver and the CNN take.

Algorithm 1 assigns pressures to tet Gauss points (centroids). The nodal field is
p_n = p0 + sum_t V_t (p_t - p0) / sum_t V_t over the tets t around node n, unvisited tets
sitting at p0: a volume-weighted mean of the excess pressure, so p0 stays exactly p0 away from
the walk and every nodal value lies within the range of its tets.
"""

from __future__ import annotations

import numpy as np


def nodal_pressure(
    tets: np.ndarray, volumes_m3: np.ndarray, p_tet_pa: np.ndarray, p0_pa: float, n_nodes: int
) -> np.ndarray:
    """Nodal pressure (n_nodes,) in Pa from tets (n_tets, 4), volumes (n_tets,), p_tet (n_tets,)."""
    excess = np.repeat(volumes_m3 * (p_tet_pa - p0_pa), 4)
    weight = np.repeat(volumes_m3, 4)
    num = np.bincount(tets.ravel(), weights=excess, minlength=n_nodes)
    den = np.bincount(tets.ravel(), weights=weight, minlength=n_nodes)
    return p0_pa + num / den
