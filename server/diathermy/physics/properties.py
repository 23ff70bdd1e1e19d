"""Effective properties of the solid / liquid / vapor mixture (PHYSICS.md section 3).

Mass fractions: solid 1 - w, liquid w (1 - x), vapor w x, with x the vapor fraction of the water.
Each property mixes its three phase values with these weights (the paper's rule); at x = 0 this
gives rho 1019.8 kg/m^3, c 3441 J/(kg K), k 0.574 W/(m K). Arrays are nodal (n,) unless noted.
"""

from __future__ import annotations

import numpy as np

from diathermy.physics.eos import vapor_density
from diathermy.physics.materials import Tissue

ArrayF = np.ndarray


def _mix(
    x: ArrayF | float, solid: float, liquid: ArrayF | float, vapor: ArrayF | float, w: float
) -> ArrayF:
    """(1 - w) solid + w [(1 - x) liquid + x vapor]."""
    x = np.asarray(x, dtype=float)
    return (1.0 - w) * solid + w * ((1.0 - x) * liquid + x * vapor)


def effective_density(
    x: ArrayF | float, p: ArrayF | float, T: ArrayF | float, tissue: Tissue
) -> ArrayF:
    """rho in kg/m^3, with the vapor density from the ideal gas at the local p (Pa) and T (K)."""
    rho_v = vapor_density(p, T, tissue)
    return _mix(
        x, tissue.rho_solid_kg_per_m3, tissue.rho_water_kg_per_m3, rho_v, tissue.water_content
    )


def effective_heat_capacity(x: ArrayF | float, tissue: Tissue) -> ArrayF:
    """c in J/(kg K)."""
    t = tissue
    return _mix(
        x, t.c_solid_j_per_kg_k, t.c_water_j_per_kg_k, t.c_vapor_j_per_kg_k, t.water_content
    )


def effective_conductivity(x: ArrayF | float, tissue: Tissue) -> ArrayF:
    """k in W/(m K)."""
    t = tissue
    return _mix(x, t.k_solid_w_per_m_k, t.k_water_w_per_m_k, t.k_vapor_w_per_m_k, t.water_content)


def volumetric_heat_capacity(
    x: ArrayF | float, p: ArrayF | float, T: ArrayF | float, tissue: Tissue
) -> ArrayF:
    """rho c in J/(m^3 K), the per-node coefficient of the heat step (and of the energy balance)."""
    return effective_density(x, p, T, tissue) * effective_heat_capacity(x, tissue)
