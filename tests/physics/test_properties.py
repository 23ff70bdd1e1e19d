"""Effective properties of the solid / liquid / vapor mixture (PHYSICS.md 3)."""

from __future__ import annotations

import numpy as np
import pytest

from diathermy.mesh import Grid, build_tet_mesh
from diathermy.mesh.kuhn_fields import tet_mean
from diathermy.physics.eos import (
    equilibrium_pressure,
    equilibrium_vapor_fraction,
    water_mass_density,
)
from diathermy.physics.materials import Tissue
from diathermy.physics.properties import (
    effective_conductivity,
    effective_density,
    effective_heat_capacity,
    volumetric_heat_capacity,
)

TISSUE = Tissue()
P0, TB = TISSUE.p_atm_pa, TISSUE.t_boil_k


def reference_property(x, p, T, tissue, name):
    """Mass-fraction weights times phase values, one node at a time."""
    w, t = tissue.water_content, tissue
    phases = {
        "rho": (t.rho_solid_kg_per_m3, t.rho_water_kg_per_m3, p / (t.r_vapor_j_per_kg_k * T)),
        "c": (t.c_solid_j_per_kg_k, t.c_water_j_per_kg_k, t.c_vapor_j_per_kg_k),
        "k": (t.k_solid_w_per_m_k, t.k_water_w_per_m_k, t.k_vapor_w_per_m_k),
    }[name]
    fractions = (1.0 - w, w * (1.0 - x), w * x)
    return sum(f * v for f, v in zip(fractions, phases, strict=True))


def test_intact_tissue_values():
    x, T = np.zeros(3), np.array([310.15, 350.0, 373.15])
    assert np.allclose(effective_density(x, P0, T, TISSUE), 1019.8, rtol=1e-14)
    assert np.all(np.round(effective_heat_capacity(x, TISSUE)) == 3441.0)
    assert np.all(np.round(effective_conductivity(x, TISSUE), 3) == 0.574)
    assert water_mass_density(TISSUE) == pytest.approx(0.7 * 1019.8, rel=1e-14)


def test_vapor_density_is_the_ideal_gas_not_a_liquid():
    T = 400.0
    p = float(equilibrium_pressure(T, TISSUE))
    dry = float(effective_density(1.0, p, T, TISSUE))
    assert dry == pytest.approx(0.3 * 1080.0 + 0.7 * p / (462.0 * T), rel=1e-14)
    assert dry < 330.0  # a vapor of 1e3 kg/m^3 would leave it near 1e3


def test_properties_fall_monotonically_with_vapor_fraction():
    x = np.linspace(0.0, 1.0, 1001)
    for T in (380.0, 450.0, 560.0, 1500.0):
        p = equilibrium_pressure(T, TISSUE)
        for values in (
            effective_density(x, p, T, TISSUE),
            effective_heat_capacity(x, TISSUE),
            effective_conductivity(x, TISSUE),
            volumetric_heat_capacity(x, p, T, TISSUE),
        ):
            assert np.all(np.diff(values) < 0)


def test_vectorised_properties_equal_scalar_twin(rng):
    T = rng.uniform(300.0, 700.0, 200)
    x = equilibrium_vapor_fraction(T, TISSUE)
    p = equilibrium_pressure(T, TISSUE)
    fast = {
        "rho": effective_density(x, p, T, TISSUE),
        "c": effective_heat_capacity(x, TISSUE),
        "k": effective_conductivity(x, TISSUE),
    }
    for name, values in fast.items():
        twin = [reference_property(x[i], p[i], T[i], TISSUE, name) for i in range(T.size)]
        assert np.allclose(values, twin, rtol=1e-14, atol=0)
    assert np.array_equal(volumetric_heat_capacity(x, p, T, TISSUE), fast["rho"] * fast["c"])


def test_tet_mean_equals_loop(small_mesh, rng):
    """The Kuhn-sliced tet mean (what the engine uses for nodal properties per tet) is the mean
    of each tet's 4 nodal values, on a uniform and a graded grid."""
    graded = build_tet_mesh(
        Grid.from_axes([0.0, 1e-3, 3e-3], [0.0, 2e-3, 2.5e-3, 6e-3], [0.0, 5e-3, 6e-3])
    )
    for mesh in (small_mesh, graded):
        values = rng.normal(size=mesh.n_nodes)
        got = tet_mean(values, mesh.grid)
        assert got.shape == (mesh.n_tets,)
        assert np.allclose(got, values[mesh.tets].mean(axis=1), rtol=1e-14, atol=1e-15)
