"""Material parameters of hydrated soft tissue (PHYSICS.md section 1 and 3), SI units."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from diathermy.errors import SceneError


@dataclass(frozen=True)
class Tissue:
    """Every material parameter of the model, with the paper's defaults (Appendix I).

    Attributes are SI: conductivities in S/m and W/(m K), densities in kg/m^3, heat capacities in
    J/(kg K), moduli and pressures in Pa, energies in J/m^3, temperatures in K.
    """

    sigma_s_per_m: float = 0.33  # electrical conductivity of healthy tissue
    sigma_removed_s_per_m: float = 1e-5  # conductivity of removed tissue (vapor/air) [ours]
    k_solid_w_per_m_k: float = 0.512
    k_water_w_per_m_k: float = 0.6
    k_vapor_w_per_m_k: float = 0.03
    rho_solid_kg_per_m3: float = 1080.0
    rho_water_kg_per_m3: float = 994.0
    water_content: float = 0.70  # mass fraction w of water
    c_solid_j_per_kg_k: float = 1700.0
    c_water_j_per_kg_k: float = 4187.0
    c_vapor_j_per_kg_k: float = 1996.0
    r_vapor_j_per_kg_k: float = 462.0  # specific gas constant of water vapor
    latent_heat_j_per_kg: float = 2.257e6  # h_fg [ours]
    youngs_modulus_pa: float = 0.27e6
    poisson_ratio: float = 0.4
    damage_kappa_j_per_m3: float = 0.7e5
    ersatz_stiffness_ratio: float = 1e-6  # E of removed tissue / E
    pore_stiffness: Literal["bulk", "oedometric_shear"] = "bulk"  # K_m = K or 4G/3
    h_convective_w_per_m2_k: float = 25.0
    t_initial_k: float = 310.15
    t_ambient_k: float = 298.15
    p_atm_pa: float = 101325.0
    t_boil_k: float = 373.15  # saturation temperature at p_atm

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if isinstance(value, float) and not value == value:  # NaN
                raise SceneError(f"material.{name} must be a number, got NaN")
        if not 0.0 < self.water_content < 1.0:
            raise SceneError(f"material.water_content must lie in (0, 1), got {self.water_content}")
        if not -1.0 < self.poisson_ratio < 0.5:
            raise SceneError(
                f"material.poisson_ratio must lie in (-1, 0.5), got {self.poisson_ratio}"
            )
        positive = (
            "sigma_s_per_m", "k_solid_w_per_m_k", "k_water_w_per_m_k", "k_vapor_w_per_m_k",
            "rho_solid_kg_per_m3", "rho_water_kg_per_m3", "c_solid_j_per_kg_k", "c_water_j_per_kg_k",
            "c_vapor_j_per_kg_k", "r_vapor_j_per_kg_k", "latent_heat_j_per_kg", "youngs_modulus_pa",
            "damage_kappa_j_per_m3", "ersatz_stiffness_ratio", "t_initial_k", "t_ambient_k",
            "p_atm_pa", "t_boil_k", "sigma_removed_s_per_m",
        )  # fmt: skip
        for name in positive:
            if not getattr(self, name) > 0:
                raise SceneError(f"material.{name} must be positive, got {getattr(self, name)}")
        if self.h_convective_w_per_m2_k < 0:
            raise SceneError("material.h_convective_w_per_m2_k must be >= 0")

    @property
    def bulk_modulus_pa(self) -> float:
        """K = E / (3 (1 - 2 nu))."""
        return self.youngs_modulus_pa / (3.0 * (1.0 - 2.0 * self.poisson_ratio))

    @property
    def shear_modulus_pa(self) -> float:
        """G = E / (2 (1 + nu))."""
        return self.youngs_modulus_pa / (2.0 * (1.0 + self.poisson_ratio))

    @property
    def pore_modulus_pa(self) -> float:
        """K_m, the stiffness confining a micropore: K by default, 4G/3 as an option."""
        if self.pore_stiffness == "bulk":
            return self.bulk_modulus_pa
        return 4.0 * self.shear_modulus_pa / 3.0


def ersatz_youngs_modulus(
    healthy: np.ndarray, youngs_modulus_pa: float, ersatz_ratio: float
) -> np.ndarray:
    """E per tet in Pa: the tissue's where healthy, the ersatz ratio E of removed tissue elsewhere.

    The one place of the ersatz-material rule (removed tets stay in the mesh, nearly void).
    ``healthy``: a mask (n_tets,), or each tet's tissue share in [0, 1] (``level_set.removal``
    'fraction'), which blends the two moduli (``share_blend``).
    """
    h = np.asarray(healthy)
    if h.dtype != bool:
        return share_blend(h, youngs_modulus_pa, ersatz_ratio * youngs_modulus_pa)
    return np.where(h, youngs_modulus_pa, ersatz_ratio * youngs_modulus_pa)


def share_blend(
    share: np.ndarray, tissue_value: np.ndarray | float, removed_value: np.ndarray | float
) -> np.ndarray:
    """A property per tet (n_tets,) of tets that are partly cut: share x the tissue's value +
    (1 - share) x the removed tissue's, with ``share`` (n_tets,) in [0, 1] the tissue left in
    each (``topology.tissue_share``). The rule of ``level_set.removal`` 'fraction': properties
    continuous in the level set, where the half-volume threshold switches them in one step."""
    s = np.asarray(share, dtype=float)
    return s * tissue_value + (1.0 - s) * removed_value
