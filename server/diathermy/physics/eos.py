"""Micromechanical vapor-pressure equation of state (PHYSICS.md section 3), vectorised over nodes.

A micropore holds water of mass rho_w V0; a mass fraction x of it is ideal-gas vapor, the liquid
is incompressible, and the matrix confines the pore with stiffness K_m (``Tissue.pore_modulus_pa``):

    p - p0 = K_m x (rho_w r T / p - 1)                          (EOS)
    p_sat(T) = p0 exp[(h_fg / r)(1/T_boil - 1/T)]               (Clausius-Clapeyron)
    X(T) = (p_sat - p0) p_sat / (K_m (rho_w r T - p_sat))       (EOS at p = p_sat)

Domain of X (checked in the tests): X = 0 for T <= T_boil; the formula increases strictly on
(T_boil, T_crit), where p_sat(T_crit) = rho_w r T_crit (saturated vapor as dense as the liquid,
1058 K with the defaults) and diverges there, so it reaches 1 at the dry-out temperature
T_dry = X^-1(1) < T_crit (579.8 K for K_m = K, 538.3 K for K_m = 4G/3). Above T_dry every drop of
water is vapor: X = 1, and the pore pressure is the EOS at x = 1, below p_sat (superheated
vapor, never supersaturated). X is therefore clipped to [0, 1] and non-decreasing for all T > 0.
(Analytically d ln X / dT > 0 on (T_boil, T_crit) whenever T_crit < h_fg / r = 4885 K.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diathermy.errors import SolverDivergedError
from diathermy.physics.materials import Tissue

ArrayF = np.ndarray


@dataclass(frozen=True, eq=False)
class EOSState:
    """Nodal state after the local energy balance: T in K, x (vapor mass fraction), p in Pa."""

    T: ArrayF
    x: ArrayF
    p: ArrayF
    iterations: int = 0  # Newton iterations the slowest node needed (0: nothing could happen)


def _boiling_exponent(T: ArrayF, tissue: Tissue) -> ArrayF:
    """(h_fg / r)(1/T_boil - 1/T), written without the cancellation of 1/T_boil - 1/T."""
    a = tissue.latent_heat_j_per_kg / tissue.r_vapor_j_per_kg_k
    return a * (T - tissue.t_boil_k) / (T * tissue.t_boil_k)


def saturation_pressure(T: ArrayF | float, tissue: Tissue) -> ArrayF:
    """Clausius-Clapeyron p_sat(T) in Pa for T (n,) in K, T > 0; p_sat(T_boil) = p0 exactly."""
    T = np.asarray(T, dtype=float)
    return tissue.p_atm_pa * np.exp(_boiling_exponent(T, tissue))


def _saturation_excess(T: ArrayF, tissue: Tissue) -> ArrayF:
    """p_sat(T) - p0 in Pa, accurate near T_boil."""
    return tissue.p_atm_pa * np.expm1(_boiling_exponent(T, tissue))


def _fraction_terms(T: ArrayF, tissue: Tissue) -> tuple[ArrayF, ArrayF, ArrayF, ArrayF]:
    """p_sat, N = (p_sat - p0) p_sat, D = rho_w r T - p_sat and the mask 0 < X(T) < 1."""
    p_sat = saturation_pressure(T, tissue)
    numer = _saturation_excess(T, tissue) * p_sat
    denom = tissue.rho_water_kg_per_m3 * tissue.r_vapor_j_per_kg_k * T - p_sat
    interior = (numer > 0) & (numer < tissue.pore_modulus_pa * denom)
    return p_sat, numer, denom, interior


def equilibrium_vapor_fraction(T: ArrayF | float, tissue: Tissue) -> ArrayF:
    """X(T) = max(0, (p_sat - p0) / (K_m (rho_w r T / p_sat - 1))), clipped to 1 past dry-out.

    T (n,) in K; returns the vapor mass fraction (n,) in [0, 1], non-decreasing in T.
    """
    T = np.asarray(T, dtype=float)
    _, numer, denom, interior = _fraction_terms(T, tissue)
    dry = (numer > 0) & ~interior
    safe = np.where(interior, tissue.pore_modulus_pa * denom, 1.0)
    return np.where(interior, numer / safe, np.where(dry, 1.0, 0.0))


def _vapor_fraction_slope(T: ArrayF, tissue: Tissue) -> ArrayF:
    """dX/dT in 1/K (n,); zero where X is 0 or 1 (one-sided at the kinks T_boil and T_dry)."""
    p_sat, numer, denom, interior = _fraction_terms(T, tissue)
    a = tissue.latent_heat_j_per_kg / tissue.r_vapor_j_per_kg_k
    dp_sat = p_sat * a / T**2
    dnumer = dp_sat * (2.0 * p_sat - tissue.p_atm_pa)
    ddenom = tissue.rho_water_kg_per_m3 * tissue.r_vapor_j_per_kg_k - dp_sat
    safe = np.where(interior, denom, 1.0)
    slope = (dnumer * safe - numer * ddenom) / (tissue.pore_modulus_pa * safe**2)
    return np.where(interior, slope, 0.0)


def pore_overpressure(x: ArrayF | float, T: ArrayF | float, tissue: Tissue) -> ArrayF:
    """p - p0 in Pa from the EOS for vapor fraction x in [0, 1] and T in K (broadcast).

    The root of dp^2 + (p0 + K_m x) dp - K_m x (rho_w r T - p0) = 0 in the form
    2c / (b + sqrt(b^2 + 4c)): no cancellation for small x, exactly 0 at x = 0.
    """
    x = np.asarray(x, dtype=float)
    T = np.asarray(T, dtype=float)
    p0, Kx = tissue.p_atm_pa, tissue.pore_modulus_pa * x
    rho_r = tissue.rho_water_kg_per_m3 * tissue.r_vapor_j_per_kg_k
    root = np.sqrt((p0 - Kx) ** 2 + 4.0 * Kx * rho_r * T)  # = sqrt(b^2 + 4c), a sum of squares
    return 2.0 * Kx * (rho_r * T - p0) / ((p0 + Kx) + root)


def pore_pressure(x: ArrayF | float, T: ArrayF | float, tissue: Tissue) -> ArrayF:
    """p(x, T) in Pa, the positive root of the quadratic EOS (p0 at x = 0)."""
    return tissue.p_atm_pa + pore_overpressure(x, T, tissue)


def vapor_density(p: ArrayF | float, T: ArrayF | float, tissue: Tissue) -> ArrayF:
    """Ideal-gas vapor density p / (r T) in kg/m^3 (0.59 at p0 and 373 K)."""
    return np.asarray(p, dtype=float) / (tissue.r_vapor_j_per_kg_k * np.asarray(T, dtype=float))


def equilibrium_pressure(T: ArrayF | float, tissue: Tissue) -> ArrayF:
    """Pore pressure at phase equilibrium, Pa: max(p0, p_sat(T)) while liquid is left, p(1, T) after."""
    T = np.asarray(T, dtype=float)
    wet = np.maximum(tissue.p_atm_pa, saturation_pressure(T, tissue))
    return np.where(equilibrium_vapor_fraction(T, tissue) < 1.0, wet, pore_pressure(1.0, T, tissue))


def temperature_for_vapor_fraction(
    x: ArrayF | float, tissue: Tissue, *, max_iter: int = 30, rtol: float = 1e-14
) -> ArrayF:
    """X^-1(x) in K for x (n,) in [0, 1]: T_boil at x = 0, the dry-out temperature at x = 1.

    Solves ln p_sat(T) = ln p(x, T) by Newton in u = 1/T, where ln p_sat is linear and
    d ln p / dT < 1/T keeps the derivative within [-a, -a + T] (a = h_fg / r): from u = 1/T_boil
    it converges in a handful of steps. Raises SolverDivergedError if it does not.
    """
    x = np.asarray(x, dtype=float)
    if np.any(~np.isfinite(x)) or np.any((x < 0.0) | (x > 1.0)):
        raise ValueError("temperature_for_vapor_fraction: x must lie in [0, 1]")
    a = tissue.latent_heat_j_per_kg / tissue.r_vapor_j_per_kg_k
    p0, Kx = tissue.p_atm_pa, tissue.pore_modulus_pa * x
    rho_r = tissue.rho_water_kg_per_m3 * tissue.r_vapor_j_per_kg_k
    u = np.full(x.shape, 1.0 / tissue.t_boil_k)
    for _ in range(max_iter):
        T = 1.0 / u
        dp = pore_overpressure(x, T, tissue)
        F = _boiling_exponent(T, tissue) - np.log1p(dp / p0)
        p = p0 + dp
        dlnp_dT = Kx * rho_r / (p * np.sqrt((p0 - Kx) ** 2 + 4.0 * Kx * rho_r * T))
        du = F / (-a + T**2 * dlnp_dT)
        u = u - du
        if np.all(np.abs(du) <= rtol * u):
            return np.where(x == 0.0, tissue.t_boil_k, 1.0 / u)
    raise SolverDivergedError(
        "temperature_for_vapor_fraction did not converge", iterations=max_iter,
        residual=float(np.max(np.abs(du) / u)),
    )  # fmt: skip


def _balance(
    T: ArrayF, T_star: ArrayF, x_old: ArrayF, rho_c: ArrayF, latent: ArrayF, tissue: Tissue
) -> tuple[ArrayF, ArrayF]:
    """g(T) = rho c (T - T*) + m_w h_fg (X(T) - x_old) in J/m^3 and its derivative."""
    g = rho_c * (T - T_star) + latent * (equilibrium_vapor_fraction(T, tissue) - x_old)
    return g, rho_c + latent * _vapor_fraction_slope(T, tissue)


def _solve_balance(
    T_star: ArrayF, x_old: ArrayF, rho_c: ArrayF, latent: ArrayF, tissue: Tissue,
    nodes: ArrayF, max_iter: int, rtol: float,
) -> tuple[ArrayF, int]:  # fmt: skip
    """Safeguarded Newton on g over all given nodes at once; bisection inside the bracket."""
    t_old = np.where(x_old > 0.0, temperature_for_vapor_fraction(x_old, tissue), tissue.t_boil_k)
    lo, hi = np.minimum(T_star, t_old), np.maximum(T_star, t_old)
    T = T_star.copy()
    last_step = np.full(T.size, np.inf)  # rtsafe: bisect unless Newton halves the last step
    pending = np.arange(T.size)
    for it in range(1, max_iter + 1):
        i, Ti = pending, T[pending]
        g, dg = _balance(Ti, T_star[i], x_old[i], rho_c[i], latent[i], tissue)
        lo[i] = np.where(g < 0.0, Ti, lo[i])
        hi[i] = np.where(g > 0.0, Ti, hi[i])
        step = g / dg
        tol = rtol * Ti
        newton = (np.abs(step) <= tol) | (
            (Ti - step > lo[i]) & (Ti - step < hi[i]) & (np.abs(step) <= 0.5 * last_step[i])
        )
        T_new = np.where(g == 0.0, Ti, np.where(newton, Ti - step, 0.5 * (lo[i] + hi[i])))
        done = (g == 0.0) | (np.abs(T_new - Ti) <= tol) | (hi[i] - lo[i] <= tol)
        last_step[i] = np.abs(T_new - Ti)
        T[i] = T_new
        pending = pending[~done]
        if pending.size == 0:
            return T, it
    g, _ = _balance(
        T[pending], T_star[pending], x_old[pending], rho_c[pending], latent[pending], tissue
    )
    rel = np.abs(g) / (rho_c[pending] * T_star[pending])
    w = int(np.argmax(rel))
    k = pending[w]
    raise SolverDivergedError(
        f"local energy balance did not converge in {max_iter} iterations at node {int(nodes[k])} "
        f"(T* = {T_star[k]:.6g} K, x_old = {x_old[k]:.6g}, relative residual {rel[w]:.3g})",
        iterations=max_iter, residual=float(rel[w]),
    )  # fmt: skip


def water_mass_density(tissue: Tissue) -> float:
    """m_w = w rho(x = 0) in kg/m^3: water (liquid + vapor) per unit volume, conserved by boiling.

    rho(x = 0) = (1 - w) rho_solid + w rho_water (no vapor yet): 713.86 kg/m^3 with the defaults.
    """
    w = tissue.water_content
    intact = (1.0 - w) * tissue.rho_solid_kg_per_m3 + w * tissue.rho_water_kg_per_m3
    return float(w * intact)


def latent_heat_per_volume(tissue: Tissue) -> float:
    """m_w h_fg in J/m^3: the latent heat stored per unit volume at x = 1 (stored: m_w h_fg x)."""
    return water_mass_density(tissue) * tissue.latent_heat_j_per_kg


def local_energy_balance(
    T_star: ArrayF,
    x_old: ArrayF,
    rho_c: ArrayF | float,
    tissue: Tissue,
    *,
    water_kg_per_m3: ArrayF | float | None = None,
    max_iter: int = 50,
    rtol: float = 1e-14,
) -> EOSState:
    """Split latent heat off the heat step: solve g(T) = 0 per node, then x = X(T), p at equilibrium.

    g(T) = rho_c (T - T*) + m_w h_fg (X(T) - x_old) is increasing in T (rho_c > 0, X
    non-decreasing); its root lies in [min, max] of T* and X^-1(x_old). Vaporisation
    (T* above the saturation temperature of x_old) and condensation (below it, which releases
    latent heat) are the same equation; once all water is vapor (x = 1) the rest heats as dry
    matter with rho_c.

    Args:
        T_star: trial temperatures (n,) in K from the heat step, taken with x held at x_old
            (any array shape; node numbers in errors are flat indices).
        x_old: vapor mass fractions (n,) in [0, 1] before the step.
        rho_c: the volumetric heat capacity (n,) in J/(m^3 K) that the heat step used,
            ``properties.volumetric_heat_capacity`` at the old state, held fixed here.
        water_kg_per_m3: m_w, the water (liquid + vapor) mass per unit tissue volume, conserved
            while it changes phase in the confined pore: w rho_0 with rho_0 the density at x = 0
            (``properties.water_mass_density``, 713.86 kg/m^3), the default.

    Energy accounting closes exactly with this split: with V_i the lumped nodal volumes, the
    latent heat stored is E_lat = sum_i V_i m_w,i h_fg x_i, and per step
    sum_i V_i [rho_c,i (T_i - T_i^old) + m_w,i h_fg (x_i - x_old,i)] equals the heat the thermal
    step put in, sum_i V_i rho_c,i (T*_i - T_i^old), to the solver tolerance (|g| <~ 1e-14 rho_c T*).

    Only nodes with T* > T_boil or x_old > 0 are solved; every other node returns T = T*
    bitwise, x = 0 and p = p0 exactly. Raises SolverDivergedError naming the worst node.
    """
    T_star, x_old, rho_c = np.broadcast_arrays(
        *(np.asarray(a, dtype=float) for a in (T_star, x_old, rho_c))
    )
    shape = T_star.shape  # any node layout, e.g. grid-shaped (nz, ny, nx); solved flat
    T_star, x_old, rho_c = T_star.ravel(), x_old.ravel(), rho_c.ravel()
    if not np.all(np.isfinite(T_star)):
        bad = int(np.flatnonzero(~np.isfinite(T_star))[0])
        raise SolverDivergedError(
            f"local energy balance: trial temperature at node {bad} is not finite"
        )
    if np.any(~((x_old >= 0.0) & (x_old <= 1.0))):
        raise ValueError("local_energy_balance: x_old must lie in [0, 1]")
    T, x = T_star.copy(), np.zeros(T_star.shape)
    p = np.full(T_star.shape, tissue.p_atm_pa)
    nodes = np.flatnonzero((T_star > tissue.t_boil_k) | (x_old > 0.0))
    if nodes.size == 0:
        return EOSState(T.reshape(shape), x.reshape(shape), p.reshape(shape), 0)
    if not np.all(rho_c[nodes] > 0.0) or not np.all(T_star[nodes] > 0.0):
        raise ValueError("local_energy_balance: rho_c and T* must be positive")
    if water_kg_per_m3 is None:
        water_kg_per_m3 = water_mass_density(tissue)
    latent = np.broadcast_to(np.asarray(water_kg_per_m3, float), T_star.shape)[nodes]
    latent = latent * tissue.latent_heat_j_per_kg
    T_a, iterations = _solve_balance(
        T_star[nodes], x_old[nodes], rho_c[nodes], latent, tissue, nodes, max_iter, rtol
    )
    T[nodes] = T_a
    x[nodes] = equilibrium_vapor_fraction(T_a, tissue)
    p[nodes] = equilibrium_pressure(T_a, tissue)
    return EOSState(T.reshape(shape), x.reshape(shape), p.reshape(shape), iterations)
