"""The convective semi-infinite solid (PHYSICS.md 6b) run on a 1D column of tets: one reference
for the uniform and the graded heat tests."""

from __future__ import annotations

import numpy as np
from scipy.special import erfc, erfcx

from diathermy.mesh import TetMesh
from diathermy.physics.heat_operator import HeatMesh
from diathermy.physics.thermal import HeatStepper

H_W_PER_M2_K, T_INF_K, T_INITIAL_K, T_END_S, DT_S = 500.0, 373.15, 298.15, 60.0, 0.1


def convective_solution(depth_m: np.ndarray, t_s: float, *, k: float, rho_c: float) -> np.ndarray:
    """(T - Ti)/(T_inf - Ti) = erfc(xi) - exp(-xi^2) erfcx(xi + beta) at ``depth_m`` below the
    convective surface, in K."""
    alpha = k / rho_c
    xi = depth_m / (2 * np.sqrt(alpha * t_s))
    beta = H_W_PER_M2_K * np.sqrt(alpha * t_s) / k
    shape = erfc(xi) - np.exp(-(xi**2)) * erfcx(xi + beta)
    return T_INITIAL_K + (T_INF_K - T_INITIAL_K) * shape


def column_max_error(mesh: TetMesh, hm: HeatMesh, *, k: float, rho_c: float) -> float:
    """Max |T - exact| (K) after T_END_S of CN steps on a column heated through its top (z+)."""
    stepper = HeatStepper(hm, h_w_per_m2_k={"z+": H_W_PER_M2_K}, t_ambient_k=T_INF_K)
    T = np.full(mesh.n_nodes, T_INITIAL_K)
    for _ in range(round(T_END_S / DT_S)):
        T = stepper.step(T, DT_S, rho_c=rho_c, k=k).T
    depth = mesh.points[:, 2].max() - mesh.points[:, 2]
    return float(np.abs(T - convective_solution(depth, T_END_S, k=k, rho_c=rho_c)).max())
