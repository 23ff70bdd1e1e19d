"""Optional tissue effects: conductivity law and Arrhenius damage (PHYSICS.md 3)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from diathermy.errors import SceneError
from diathermy.physics.materials import Tissue
from diathermy.physics.tissue_effects import (
    GAS_CONSTANT_J_PER_MOL_K,
    ArrheniusDamage,
    ConductivityLaw,
    arrhenius_damage_increment,
    damage_fraction,
    electrical_conductivity,
)

TISSUE = Tissue()
DAMAGE = ArrheniusDamage()
A, B = DAMAGE.frequency_factor_per_s, DAMAGE.activation_temperature_k


@pytest.mark.parametrize(
    ("T", "x", "sigma"),
    [
        (310.15, 0.0, 0.33),
        (350.15, 0.0, 0.33 * 1.6),
        (373.15, 0.0, 0.33 * (1 + 0.015 * 63.0)),
        (450.0, 0.0, 0.33 * (1 + 0.015 * 63.0)),  # capped at T_boil
        (400.0, 0.5, 0.5 * 0.33 * (1 + 0.015 * 63.0)),
        (298.15, 0.0, 0.33 * (1 - 0.015 * 12.0)),
        (500.0, 1.0, 1e-5),  # dry: the floor
        (200.0, 0.0, 1e-5),  # the linear law would go negative
    ],
)
def test_conductivity_values(T, x, sigma):
    assert electrical_conductivity(np.array([T]), np.array([x]), TISSUE)[0] == pytest.approx(
        sigma, rel=1e-13
    )


def test_conductivity_options():
    T, x = np.array([330.15, 330.15]), np.array([0.0, 0.6])
    law = ConductivityLaw(
        temperature_coefficient_per_k=0.02, reference_temperature_k=320.15, desiccation=False
    )
    assert np.allclose(electrical_conductivity(T, x, TISSUE, law), 0.33 * 1.2, rtol=1e-14)
    flat = ConductivityLaw(temperature_coefficient_per_k=0.0)
    assert np.allclose(electrical_conductivity(T, x, TISSUE, flat), [0.33, 0.33 * 0.4], rtol=1e-14)
    sigma = electrical_conductivity(np.full(101, 400.0), np.linspace(0, 1, 101), TISSUE)
    assert np.all(np.diff(sigma) <= 0) and sigma.min() == TISSUE.sigma_removed_s_per_m


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (
            lambda: ConductivityLaw(temperature_coefficient_per_k=-0.01),
            "temperature_coefficient_per_k",
        ),
        (
            lambda: ConductivityLaw(temperature_coefficient_per_k=float("nan")),
            "temperature_coefficient_per_k",
        ),
        (lambda: ConductivityLaw(reference_temperature_k=0.0), "reference_temperature_k"),
        (lambda: ArrheniusDamage(frequency_factor_per_s=0.0), "frequency_factor_per_s"),
        (
            lambda: ArrheniusDamage(activation_energy_j_per_mol=float("inf")),
            "activation_energy_j_per_mol",
        ),
        (
            lambda: electrical_conductivity(
                np.ones(1), np.zeros(1), Tissue(sigma_removed_s_per_m=1.0)
            ),
            "sigma_removed_s_per_m",
        ),
    ],
)
def test_bad_parameters_are_rejected(make, message):
    with pytest.raises(SceneError, match=message):
        make()


def test_damage_increment_at_constant_temperature_is_closed_form():
    T = np.array([310.15, 330.0, 343.15, 373.15, 500.0, 2000.0])
    dt = 0.03
    exact = A * np.exp(-2.577e5 / (GAS_CONSTANT_J_PER_MOL_K * T)) * dt
    assert np.allclose(arrhenius_damage_increment(T, T, dt), exact, rtol=1e-14, atol=0)
    assert B == pytest.approx(30994.19, abs=0.01)


def reference_increment(T0, T1, dt):
    """Adaptive quadrature of A exp(-b / T(t)) with T linear, scaled to avoid underflow."""
    z = B / max(T0, T1)
    scaled, _ = quad(
        lambda s: math.exp(z - B / (T0 + (T1 - T0) * s)),
        0.0,
        1.0,
        epsabs=0,
        epsrel=1e-13,
        limit=200,
    )
    return A * dt * math.exp(-z) * scaled


@pytest.mark.parametrize(
    ("T0", "T1"),
    [
        (310.15, 311.0),
        (311.0, 310.15),
        (310.0, 400.0),
        (400.0, 520.0),
        (300.0, 2000.0),
        (150.0, 300.0),
        (330.0, 330.0 + 1e-7),
    ],
)
def test_damage_increment_is_exact_for_linear_temperature(T0, T1):
    got = arrhenius_damage_increment(np.array([T0]), np.array([T1]), 0.03)[0]
    assert got == pytest.approx(reference_increment(T0, T1, 0.03), rel=1e-11)


def test_damage_is_additive_over_split_steps(rng):
    T0, T1 = rng.uniform(300.0, 600.0, 500), rng.uniform(300.0, 600.0, 500)
    whole = arrhenius_damage_increment(T0, T1, 0.03)
    mid = 0.5 * (T0 + T1)
    halves = arrhenius_damage_increment(T0, mid, 0.015) + arrhenius_damage_increment(mid, T1, 0.015)
    assert np.allclose(whole, halves, rtol=1e-12, atol=0)


def test_damage_is_overflow_safe_and_fraction_bounded():
    T = np.concatenate([np.linspace(40.0, 2000.0, 500), [1e6]])
    inc = arrhenius_damage_increment(T, T[::-1], 0.03)
    assert np.all(np.isfinite(inc)) and np.all(inc >= 0)
    omega = np.cumsum(np.tile(inc, 400))  # 400 steps of the worst case stay finite
    frac = damage_fraction(omega)
    assert np.all(np.isfinite(omega)) and np.all((frac >= 0) & (frac <= 1))
    assert damage_fraction(np.array([0.0]))[0] == 0.0
    assert damage_fraction(np.array([1e-20]))[0] == pytest.approx(1e-20)
    assert damage_fraction(np.array([1.0]))[0] == pytest.approx(1 - math.exp(-1))
    assert damage_fraction(np.array([1e300]))[0] == 1.0


def test_damage_rejects_bad_input():
    with pytest.raises(ValueError, match="positive"):
        arrhenius_damage_increment(np.array([0.0]), np.array([300.0]), 0.03)
    with pytest.raises(ValueError, match="finite"):
        arrhenius_damage_increment(np.array([np.inf]), np.array([300.0]), 0.03)
    with pytest.raises(ValueError, match="dt_s"):
        arrhenius_damage_increment(np.array([300.0]), np.array([300.0]), -1.0)
