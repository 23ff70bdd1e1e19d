"""Optional tissue effects (PHYSICS.md section 3), off unless a scene asks for them.

- Electrical conductivity that rises with temperature below boiling and falls as the tissue
  dries out.
- Arrhenius thermal damage Omega = int A exp(-Ea / (R T)) dt and the damaged fraction
  1 - exp(-Omega) (the collateral burn map).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import exp1

from diathermy.errors import SceneError
from diathermy.physics.materials import Tissue

ArrayF = np.ndarray

GAS_CONSTANT_J_PER_MOL_K = 8.314462618


def _require(ok: bool, message: str) -> None:
    if not ok:
        raise SceneError(message)


@dataclass(frozen=True)
class ConductivityLaw:
    """sigma(T, x) = max(sigma_floor, sigma0 [1 + alpha (min(T, T_boil) - T_ref)] (1 - x)).

    sigma0 and sigma_floor (the conductivity of removed tissue) come from ``Tissue``; T_ref
    defaults to ``Tissue.t_initial_k``. The factor 1 - x is the liquid water mass fraction
    w (1 - x) relative to the initial w (x = 0 at the start); ``desiccation=False`` drops it.
    """

    temperature_coefficient_per_k: float = 0.015
    reference_temperature_k: float | None = None
    desiccation: bool = True

    def __post_init__(self) -> None:
        alpha = self.temperature_coefficient_per_k
        _require(
            math.isfinite(alpha) and alpha >= 0.0,
            f"conductivity.temperature_coefficient_per_k must be a finite number >= 0, got {alpha}",
        )
        t_ref = self.reference_temperature_k
        _require(
            t_ref is None or (math.isfinite(t_ref) and t_ref > 0.0),
            f"conductivity.reference_temperature_k must be a positive temperature in K, got {t_ref}",
        )


def electrical_conductivity(
    T: ArrayF, x: ArrayF, tissue: Tissue, law: ConductivityLaw | None = None
) -> ArrayF:
    """sigma in S/m (n,) from T in K and vapor fraction x in [0, 1] (n,), never below the floor."""
    law = ConductivityLaw() if law is None else law
    sigma0, floor = tissue.sigma_s_per_m, tissue.sigma_removed_s_per_m
    _require(
        floor < sigma0,
        f"material.sigma_removed_s_per_m ({floor}) must be below sigma_s_per_m ({sigma0})",
    )
    t_ref = (
        tissue.t_initial_k if law.reference_temperature_k is None else law.reference_temperature_k
    )
    T = np.minimum(np.asarray(T, dtype=float), tissue.t_boil_k)
    sigma = sigma0 * (1.0 + law.temperature_coefficient_per_k * (T - t_ref))
    if law.desiccation:
        sigma = sigma * (1.0 - np.asarray(x, dtype=float))
    return np.maximum(sigma, floor)


@dataclass(frozen=True)
class ArrheniusDamage:
    """Arrhenius parameters (liver-like tissue): A in 1/s, Ea in J/mol."""

    frequency_factor_per_s: float = 7.39e39
    activation_energy_j_per_mol: float = 2.577e5

    def __post_init__(self) -> None:
        for name in ("frequency_factor_per_s", "activation_energy_j_per_mol"):
            value = getattr(self, name)
            _require(
                math.isfinite(value) and value > 0.0,
                f"damage.{name} must be a finite positive number, got {value}",
            )

    @property
    def activation_temperature_k(self) -> float:
        """Ea / R in K (30994 K by default)."""
        return self.activation_energy_j_per_mol / GAS_CONSTANT_J_PER_MOL_K


_GL_S, _GL_W = np.polynomial.legendre.leggauss(8)
_GL_S, _GL_W = 0.5 * (_GL_S + 1.0), 0.5 * _GL_W  # on [0, 1], weights summing to 1


def _psi(z: ArrayF) -> ArrayF:
    """psi(z) = 1/z - e^z E1(z) ~ 1/z^2, so that int e^-z / z^2 dz = -e^-z psi(z)."""
    out = np.empty_like(z)
    small = z < 200.0
    zs = z[small]
    out[small] = 1.0 / zs - np.exp(zs) * exp1(zs)
    zl = z[~small]  # asymptotic series, truncation error < 9!/z^8 relative (1e-13)
    out[~small] = sum((-1.0) ** (k + 1) * math.factorial(k) / zl ** (k + 1) for k in range(1, 9))
    return out


def _mean_arrhenius_factor(T0: ArrayF, T1: ArrayF, b: float) -> tuple[ArrayF, ArrayF]:
    """(z_max_T, m): the mean of exp(-b/T) over linear T from T0 to T1 is exp(-z) m, 0 < m <= 1."""
    T_hi, T_lo = np.maximum(T0, T1), np.minimum(T0, T1)
    z_hi, z_lo = b / T_hi, b / T_lo
    spread = z_lo - z_hi
    m = np.empty_like(T_hi)
    near = spread < 0.5  # Gauss-Legendre (8 points) is exact to round-off here
    T_q = T0[near, None] + (T1 - T0)[near, None] * _GL_S
    m[near] = np.exp(z_hi[near, None] - b / T_q) @ _GL_W
    far = ~near  # exact antiderivative; the difference loses < 1 digit since spread >= 0.5
    zh, zl = z_hi[far], z_lo[far]
    m[far] = b * (_psi(zh) - np.exp(-(zl - zh)) * _psi(zl)) / (T_hi - T_lo)[far]
    return z_hi, m


def arrhenius_damage_increment(
    T_old: ArrayF, T_new: ArrayF, dt_s: float, damage: ArrheniusDamage | None = None
) -> ArrayF:
    """Delta Omega (n,) over a step of dt_s, exact for T linear in time from T_old to T_new (K).

    int_0^dt A exp(-Ea / (R T(t))) dt = A dt mean(exp(-b/T)); with b = Ea/R the mean is the
    closed form b [e^-z psi(z)]_{b/T_lo}^{b/T_hi} / (T_hi - T_lo), psi(z) = 1/z - e^z E1(z),
    and 8-point Gauss-Legendre where the endpoints are too close for the difference. Finite
    for every finite T > 0 (A exp(-b/T) <= A).
    """
    damage = ArrheniusDamage() if damage is None else damage
    T_old, T_new = np.broadcast_arrays(np.asarray(T_old, float), np.asarray(T_new, float))
    if not (np.all(np.isfinite(T_old)) and np.all(np.isfinite(T_new))):
        raise ValueError("arrhenius_damage_increment: temperatures must be finite")
    if np.any(T_old <= 0.0) or np.any(T_new <= 0.0):
        raise ValueError("arrhenius_damage_increment: temperatures must be positive (K)")
    if not (math.isfinite(dt_s) and dt_s >= 0.0):
        raise ValueError(f"arrhenius_damage_increment: dt_s must be finite and >= 0, got {dt_s}")
    z, m = _mean_arrhenius_factor(T_old.ravel(), T_new.ravel(), damage.activation_temperature_k)
    rate = np.exp(math.log(damage.frequency_factor_per_s) - z) * m
    return (dt_s * rate).reshape(T_old.shape)


def damage_fraction(omega: ArrayF) -> ArrayF:
    """Fraction of damaged tissue 1 - exp(-Omega) in [0, 1] for Omega >= 0."""
    return -np.expm1(-np.asarray(omega, dtype=float))
