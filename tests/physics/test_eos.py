"""The vapor-pressure EOS and the local energy balance (PHYSICS.md 3 and 6f)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

from diathermy.errors import SolverDivergedError
from diathermy.physics.eos import (
    _vapor_fraction_slope,
    equilibrium_pressure,
    equilibrium_vapor_fraction,
    local_energy_balance,
    pore_overpressure,
    pore_pressure,
    saturation_pressure,
    temperature_for_vapor_fraction,
    vapor_density,
    water_mass_density,
)
from diathermy.physics.materials import Tissue

TISSUE = Tissue()
SOFT = Tissue(pore_stiffness="oedometric_shear")  # K_m = 4G/3
LATENT = water_mass_density(TISSUE) * TISSUE.latent_heat_j_per_kg  # m_w h_fg, J/m^3
TB = TISSUE.t_boil_k

REFERENCE = [  # T (K), p (kPa), x  -- PHYSICS.md 6f, K_m = K
    (373.15, 101.3, 0.0),
    (378.15, 120.5, 2.95e-5),
    (393.15, 197.2, 2.33e-4),
    (413.15, 359.9, 1.09e-3),
    (423.15, 476.0, 2.04e-3),
]


def g(T, T_star, x_old, rho_c, tissue=TISSUE):
    """The energy balance, J/m^3."""
    return rho_c * (T - T_star) + LATENT * (equilibrium_vapor_fraction(T, tissue) - x_old)


def critical_temperature(tissue):
    """p_sat(T) = rho_w r T: where the unclipped X(T) diverges."""
    rho_r = tissue.rho_water_kg_per_m3 * tissue.r_vapor_j_per_kg_k
    return brentq(lambda T: saturation_pressure(T, tissue) - rho_r * T, 500.0, 3000.0, xtol=1e-12)


def raw_vapor_fraction(T, tissue):
    """PHYSICS.md's X(T) formula as written, unclipped (T_boil < T < T_crit)."""
    ps = saturation_pressure(T, tissue)
    rho_r = tissue.rho_water_kg_per_m3 * tissue.r_vapor_j_per_kg_k
    return (ps - tissue.p_atm_pa) / (tissue.pore_modulus_pa * (rho_r * T / ps - 1.0))


def reference_inverse(x, tissue=TISSUE):
    """X^-1 by scalar bracketing of the unclipped formula, node by node."""
    out = np.full(len(x), TB)
    T_crit = critical_temperature(tissue)
    for i, xi in enumerate(x):
        if xi > 0:
            f = lambda T, xi=xi: raw_vapor_fraction(T, tissue) - xi  # noqa: E731
            out[i] = brentq(f, TB, T_crit - 1.0, xtol=1e-13, rtol=1e-15)
    return out


def reference_balance(T_star, x_old, rho_c, tissue=TISSUE):
    """The local energy balance by scalar bracketing, node by node."""
    T = np.array(T_star, dtype=float)
    for i in range(T.size):
        if T_star[i] <= TB and x_old[i] == 0:
            continue
        reach = LATENT / rho_c[i] + 1.0  # |T - T*| <= m_w h_fg |x - x_old| / rho_c
        lo, hi = max(1.0, T_star[i] - reach), T_star[i] + reach
        T[i] = brentq(
            g, lo, hi, args=(T_star[i], x_old[i], rho_c[i], tissue), xtol=1e-13, rtol=1e-15
        )
    return T


@pytest.mark.parametrize(("T", "p_kpa", "x"), REFERENCE)
def test_reference_values(T, p_kpa, x):
    assert equilibrium_pressure(T, TISSUE) / 1e3 == pytest.approx(p_kpa, rel=5e-3)
    assert equilibrium_vapor_fraction(T, TISSUE) == pytest.approx(x, rel=5e-3, abs=1e-15)
    # and p from the quadratic EOS at that x
    assert pore_pressure(equilibrium_vapor_fraction(T, TISSUE), T, TISSUE) / 1e3 == pytest.approx(
        p_kpa, rel=5e-3
    )


def test_saturation_pressure_and_vapor_density():
    assert saturation_pressure(TB, TISSUE) == TISSUE.p_atm_pa
    assert vapor_density(TISSUE.p_atm_pa, 373.0, TISSUE) == pytest.approx(0.588, abs=1e-3)


@pytest.mark.parametrize("tissue", [TISSUE, SOFT])
def test_pressure_at_equilibrium_fraction_is_saturation(tissue):
    T_dry = temperature_for_vapor_fraction(1.0, tissue)
    T = np.linspace(TB, T_dry, 2001)[1:-1]
    p = pore_pressure(equilibrium_vapor_fraction(T, tissue), T, tissue)
    assert np.allclose(p, saturation_pressure(T, tissue), rtol=1e-12, atol=0)


def test_pore_pressure_is_cancellation_free_for_small_x():
    T, rho_r = 400.0, TISSUE.rho_water_kg_per_m3 * TISSUE.r_vapor_j_per_kg_k
    K, p0 = TISSUE.pore_modulus_pa, TISSUE.p_atm_pa
    for x in (1e-300, 1e-15, 1e-12, 1e-9, 1e-7):
        b, c = p0 + K * x, K * x * (rho_r * T - p0)
        e = c / b**2  # dp = (c / b)(1 - e + 2 e^2 - ...)
        series = c / b * (1.0 - e + 2.0 * e**2)
        assert pore_overpressure(x, T, TISSUE) == pytest.approx(series, rel=5 * e**3 + 1e-15)
    assert pore_overpressure(0.0, T, TISSUE) == 0.0
    assert pore_pressure(0.0, 2000.0, TISSUE) == p0


@pytest.mark.parametrize(("tissue", "t_dry"), [(TISSUE, 579.82), (SOFT, 538.29)])
def test_vapor_fraction_is_monotone_and_where(tissue, t_dry):
    """X is 0 up to T_boil, strictly increasing up to dry-out, then 1; T_dry < T_crit."""
    T_dry = float(temperature_for_vapor_fraction(1.0, tissue))
    T_crit = critical_temperature(tissue)
    assert T_dry == pytest.approx(t_dry, abs=0.01)
    assert T_crit == pytest.approx(1058.24, abs=0.01)
    assert T_dry < T_crit < tissue.latent_heat_j_per_kg / tissue.r_vapor_j_per_kg_k
    T = np.linspace(200.0, 2000.0, 180_001)
    X = equilibrium_vapor_fraction(T, tissue)
    assert np.all((X >= 0) & (X <= 1)) and np.all(np.diff(X) >= 0)
    assert np.all(X[T <= TB] == 0) and np.all(X[T >= T_dry + 1e-9] == 1)
    wet = (T > TB) & (T < T_dry)
    assert np.all(np.diff(X[wet]) > 0)
    assert np.all(_vapor_fraction_slope(T[wet], tissue) > 0)
    # the unclipped formula keeps increasing to T_crit, where it diverges
    raw = raw_vapor_fraction(np.linspace(TB + 0.01, T_crit - 0.01, 10_001), tissue)
    assert np.all(np.diff(raw) > 0) and raw[-1] > 1e3


def test_slope_matches_finite_differences():
    T = np.linspace(374.0, 575.0, 50)
    h = 1e-4
    fd = (equilibrium_vapor_fraction(T + h, TISSUE) - equilibrium_vapor_fraction(T - h, TISSUE)) / (
        2 * h
    )
    assert np.allclose(_vapor_fraction_slope(T, TISSUE), fd, rtol=1e-6)


@pytest.mark.parametrize("tissue", [TISSUE, SOFT])
def test_inverse_vapor_fraction(tissue):
    x = np.concatenate([[0.0, 1e-12, 1e-6], np.linspace(0.0, 1.0, 101)[1:]])
    T = temperature_for_vapor_fraction(x, tissue)
    assert T[0] == TB
    assert np.allclose(equilibrium_vapor_fraction(T, tissue), x, rtol=1e-11, atol=1e-15)
    assert np.allclose(T, reference_inverse(x, tissue), rtol=1e-12)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        temperature_for_vapor_fraction(np.array([1.5]), tissue)


@settings(max_examples=300, deadline=None)
@given(
    T_star=st.floats(250.0, 2000.0),
    x_old=st.one_of(st.just(0.0), st.just(1.0), st.floats(0.0, 1.0)),
    rho_c=st.floats(1e5, 6e6),
)
def test_balance_has_exactly_one_root(T_star, x_old, rho_c):
    """g is increasing and changes sign on the bracket [T*, X^-1(x_old)]."""
    t_old = TB if x_old == 0 else float(temperature_for_vapor_fraction(x_old, TISSUE))
    lo, hi = min(T_star, t_old), max(T_star, t_old)
    assert g(lo, T_star, x_old, rho_c) <= 1e-6 and g(hi, T_star, x_old, rho_c) >= -1e-6
    T = np.linspace(max(1.0, lo - 50.0), hi + 50.0, 2001)
    assert np.all(np.diff(g(T, T_star, x_old, rho_c)) > 0)


def assert_balanced(state, T_star, x_old, rho_c):
    res = g(state.T, T_star, x_old, rho_c)
    assert np.array_equal(state.x, equilibrium_vapor_fraction(state.T, TISSUE))
    # the resolution of T itself, on the scale of the largest term of g (sensible or latent)
    latent = water_mass_density(TISSUE) * TISSUE.latent_heat_j_per_kg * np.maximum(state.x, x_old)
    assert np.all(np.abs(res) <= 1e-13 * (rho_c * np.maximum(T_star, state.T) + latent))
    exchange = rho_c * np.abs(state.T - T_star)
    big = exchange > rho_c * 1e-3  # more than a millikelvin's worth moved
    assert np.all(np.abs(res[big]) <= 1e-9 * exchange[big])
    assert np.all((state.x >= 0) & (state.x <= 1)) and np.all(np.isfinite(state.p))


@settings(max_examples=100, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(250.0, 2000.0),
            st.one_of(st.just(0.0), st.just(1.0), st.floats(0.0, 1.0)),
            st.floats(1e5, 6e6),
        ),
        min_size=1,
        max_size=20,
    )
)
def test_energy_balance_closes_per_node(nodes):
    T_star, x_old, rho_c = (np.array(a) for a in zip(*nodes, strict=True))
    state = local_energy_balance(T_star, x_old, rho_c, TISSUE)
    assert_balanced(state, T_star, x_old, rho_c)
    assert np.allclose(state.T, reference_balance(T_star, x_old, rho_c), rtol=1e-12, atol=0)


def test_vectorised_solve_equals_scalar_twin(rng):
    n = 400
    T_star = rng.uniform(300.0, 900.0, n)
    x_old = np.where(rng.uniform(size=n) < 0.5, 0.0, rng.uniform(size=n) ** 3)
    rho_c = rng.uniform(2e5, 4e6, n)
    state = local_energy_balance(T_star, x_old, rho_c, TISSUE)
    assert_balanced(state, T_star, x_old, rho_c)
    assert np.allclose(state.T, reference_balance(T_star, x_old, rho_c), rtol=1e-12, atol=0)
    assert 0 < state.iterations <= 20


def test_grid_shaped_nodes(rng):
    T_star = rng.uniform(300.0, 600.0, (4, 5, 6))
    x_old = np.where(T_star > 450.0, 0.05, 0.0)
    state = local_energy_balance(T_star, x_old, 3.5e6, TISSUE)
    flat = local_energy_balance(T_star.ravel(), x_old.ravel(), 3.5e6, TISSUE)
    for a, b in ((state.T, flat.T), (state.x, flat.x), (state.p, flat.p)):
        assert a.shape == T_star.shape and np.array_equal(a.ravel(), b)


def test_nodes_below_boiling_are_untouched_exactly(rng):
    T_star = rng.uniform(250.0, TB, 1000)
    T_star[:3] = (TB, np.nextafter(TB, 0.0), 310.15)
    state = local_energy_balance(T_star, np.zeros(1000), 3.5e6, TISSUE)
    assert np.array_equal(state.T, T_star) and state.T is not T_star
    assert np.all(state.x == 0.0) and np.all(state.p == TISSUE.p_atm_pa)
    assert state.iterations == 0
    # mixed with nodes that boil, the cold ones still come back bitwise
    T_mix = np.concatenate([T_star, [380.0, 450.0]])
    mixed = local_energy_balance(T_mix, np.zeros(1002), 3.5e6, TISSUE)
    assert np.array_equal(mixed.T[:1000], T_star) and np.all(mixed.x[:1000] == 0.0)
    assert np.all(mixed.p[:1000] == TISSUE.p_atm_pa)
    assert np.all(mixed.x[1000:] > 0) and np.all(mixed.T[1000:] < T_mix[1000:])


def test_boiling_absorbs_and_condensation_releases_latent_heat():
    state = local_energy_balance(np.array([400.0, 400.0]), np.array([0.0, 0.1]), 3.5e6, TISSUE)
    assert state.T[0] < 400.0 and state.x[0] > 0  # boils
    assert state.T[1] > 400.0 and state.x[1] < 0.1  # condenses
    # fully condensed, the node lands below boiling with x = 0 and p = p0 exactly
    cold = local_energy_balance(np.array([300.0]), np.array([1e-4]), 3.5e6, TISSUE)
    assert cold.x[0] == 0.0 and cold.p[0] == TISSUE.p_atm_pa
    assert cold.T[0] == pytest.approx(300.0 + LATENT * 1e-4 / 3.5e6, rel=1e-14)


def test_softer_pore_holds_more_vapor_at_the_same_pressure():
    T = np.linspace(374.0, 530.0, 200)
    ratio = TISSUE.pore_modulus_pa / SOFT.pore_modulus_pa
    assert ratio == pytest.approx(3.5)
    assert np.allclose(
        equilibrium_vapor_fraction(T, SOFT),
        ratio * equilibrium_vapor_fraction(T, TISSUE),
        rtol=1e-12,
    )
    assert np.array_equal(equilibrium_pressure(T, SOFT), equilibrium_pressure(T, TISSUE))
    x = np.linspace(1e-4, 1.0, 50)
    assert np.all(pore_pressure(x, 450.0, SOFT) < pore_pressure(x, 450.0, TISSUE))
    T_star = np.array([390.0, 420.0, 480.0])
    stiff = local_energy_balance(T_star, np.zeros(3), 3.5e6, TISSUE)
    soft = local_energy_balance(T_star, np.zeros(3), 3.5e6, SOFT)
    assert np.all(soft.x > stiff.x) and np.all(soft.T < stiff.T) and np.all(soft.p < stiff.p)


@settings(max_examples=200, deadline=None)
@given(T=st.floats(200.0, 2000.0), x=st.floats(0.0, 1.0))
def test_never_supersaturated(T, x):
    """Below X(T) the pore is under p_sat; at equilibrium p = p_sat; dry, p(1, T) < p_sat."""
    p_sat = float(saturation_pressure(T, TISSUE))
    X = float(equilibrium_vapor_fraction(T, TISSUE))
    if x <= X:
        assert pore_pressure(x, T, TISSUE) <= p_sat * (1 + 1e-14) or x == 0
    p_eq = float(equilibrium_pressure(T, TISSUE))
    assert p_eq <= max(TISSUE.p_atm_pa, p_sat) * (1 + 1e-15)
    state = local_energy_balance(np.array([T]), np.array([x]), 3.5e6, TISSUE)
    if state.x[0] > 0:
        assert state.p[0] <= saturation_pressure(state.T[0], TISSUE) * (1 + 1e-14)


def test_pressure_is_continuous_at_dry_out():
    T_dry = float(temperature_for_vapor_fraction(1.0, TISSUE))
    below, above = equilibrium_pressure(np.array([T_dry - 1e-9, T_dry + 1e-9]), TISSUE)
    assert above == pytest.approx(below, rel=1e-8)
    T = np.linspace(T_dry + 1e-6, 2000.0, 500)
    assert np.all(equilibrium_pressure(T, TISSUE) < saturation_pressure(T, TISSUE))


def test_extreme_temperatures_and_dry_tissue():
    T_star = np.array([2000.0, 2000.0, 2000.0, 1500.0, 700.0, 600.0])
    x_old = np.array([0.0, 0.5, 1.0, 1.0, 1.0, 0.999])
    rho_c = np.full(6, 1.5e6)
    state = local_energy_balance(T_star, x_old, rho_c, TISSUE)
    assert np.all(np.isfinite(state.T)) and np.all(np.isfinite(state.p))
    assert np.all(state.x == 1.0)
    # all water gone: the rest heats as dry matter, untouched by the EOS
    assert np.array_equal(state.T[2:5], T_star[2:5])
    assert np.array_equal(state.p[2:5], pore_pressure(1.0, T_star[2:5], TISSUE))
    # the last water boils off first, with exactly its latent heat
    expected = T_star[:2] - LATENT * (1.0 - x_old[:2]) / rho_c[:2]
    assert np.allclose(state.T[:2], expected, rtol=1e-14)
    assert_balanced(state, T_star, x_old, rho_c)


def test_failures_are_loud():
    with pytest.raises(SolverDivergedError, match="node 1 is not finite"):
        local_energy_balance(np.array([300.0, np.nan]), np.zeros(2), 3.5e6, TISSUE)
    with pytest.raises(SolverDivergedError, match=r"node 2 \(T\* = 900 K"):
        local_energy_balance(
            np.array([300.0, 380.0, 900.0]), np.array([0.0, 0.0, 0.2]), 3.5e6, TISSUE, max_iter=2
        )
    with pytest.raises(ValueError, match=r"x_old must lie in \[0, 1\]"):
        local_energy_balance(np.array([400.0]), np.array([1.2]), 3.5e6, TISSUE)
    with pytest.raises(ValueError, match="positive"):
        local_energy_balance(np.array([400.0]), np.array([0.0]), -1.0, TISSUE)
