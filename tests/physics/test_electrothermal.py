"""The coupled step: monolithic block-GMRES equals the staggered solve to solver tolerance."""

from __future__ import annotations

import numpy as np
import pytest

from diathermy.fem.geometry import structured_geometry
from diathermy.mesh import Grid, build_tet_mesh
from diathermy.physics.contact_load import contact_weights
from diathermy.physics.driven_potential import ElectrodeDrive
from diathermy.physics.electrothermal import ElectroThermal

A_M = 1.17e-3
RHO_C = 1019.8 * 3441.0
K_TISSUE = 0.574


@pytest.fixture(scope="module")
def mesh_geom():
    mesh = build_tet_mesh(Grid((17, 17, 33)))
    return mesh, structured_geometry(mesh.points, mesh.tets, mesh.shape_id)


def scene(mesh, rng):
    """Uneven coefficients, as the EOS and a cut would make them."""
    return {
        "sigma": 0.33 * rng.uniform(0.5, 1.5, mesh.n_tets),
        "rho_c": RHO_C * rng.uniform(0.9, 1.1, mesh.n_nodes),
        "k": K_TISSUE * rng.uniform(0.8, 1.2, mesh.n_tets),
    }


@pytest.mark.parametrize(
    "drive",
    [
        ElectrodeDrive(),
        ElectrodeDrive(mode="power", power_w=50.0),
        ElectrodeDrive(max_voltage_v=30.0),  # the limits hold: j0 needs ~48 V here, 50 W ~99 V
        ElectrodeDrive(mode="power", power_w=50.0, max_voltage_v=60.0),
    ],
    ids=["j0", "50W", "j0-40V", "50W-60V"],
)
@pytest.mark.parametrize("thermal_block", ["amg", "jacobi", "auto"])
def test_monolithic_equals_staggered(mesh_geom, rng, drive, thermal_block):
    """Three steps: fixed electrode, then moved, then a new conductivity and a large step."""
    mesh, geom = mesh_geom
    coeffs = scene(mesh, rng)
    stag = ElectroThermal(mesh, geom, potential_rtol=1e-10)  # both at the same tolerance
    mono = ElectroThermal(mesh, geom)
    T_s = T_m = np.full(mesh.n_nodes, 310.15)
    plan = [
        ((0.1, 0.05, 0.1), coeffs["sigma"], 0.03, 2),  # first step: linearised about V* = 0
        ((0.1, 0.05, 0.1), coeffs["sigma"], 0.03, 1),
        ((0.107, 0.052, 0.1), coeffs["sigma"], 0.03, 2),  # the electrode moved: re-linearise
        ((0.107, 0.052, 0.1), 0.9 * coeffs["sigma"], 300.0, 2),  # new sigma; theta > 1/2
    ]
    for center, sigma, dt, passes in plan:
        contact = contact_weights(mesh, center, A_M)
        kw = {"sigma": sigma, "contact": contact, "drive": drive, "rho_c": coeffs["rho_c"]}
        s = stag.staggered_step(T_s, dt, k=coeffs["k"], **kw)
        m = mono.monolithic_step(T_m, dt, k=coeffs["k"], thermal_block=thermal_block, **kw)
        assert m.picard_passes == passes
        assert np.abs(m.V - s.V).max() <= 1e-8 * np.abs(s.V).max()
        assert np.abs(m.T - s.T).max() <= 1e-8 * s.T.max()
        assert m.power_w == pytest.approx(s.power_w, rel=1e-8)
        assert m.current_a == pytest.approx(s.current_a, rel=1e-8)
        T_s, T_m = s.T, m.T
    assert s.heat.fallback_nodes.size > 0
    if drive.max_voltage_v is not None:  # held at the limit: P = V^2 / R = V I
        assert s.power_w == pytest.approx(drive.max_voltage_v * s.current_a, rel=1e-9)
    elif drive.mode == "power":
        assert s.power_w == pytest.approx(50.0, rel=1e-12)


def test_staggered_step_reuses_the_potential_and_closes_energy(mesh_geom, rng):
    mesh, geom = mesh_geom
    coeffs = scene(mesh, rng)
    solver = ElectroThermal(mesh, geom)
    contact = contact_weights(mesh, (0.1, 0.05, 0.1), A_M)
    T = np.full(mesh.n_nodes, 310.15)
    first = solver.staggered_step(T, 0.03, contact=contact, drive=ElectrodeDrive(), **coeffs)
    second = solver.staggered_step(first.T, 0.03, contact=contact, drive=ElectrodeDrive(), **coeffs)
    assert second.potential is not None and second.potential.cached
    assert np.array_equal(first.q, second.q)
    assert first.current_a == pytest.approx(5.72e4 * np.pi * A_M**2, rel=1e-10)
    assert first.joule_w == pytest.approx(first.power_w, rel=1e-6)
    e = second.energy
    assert e.joule_j == pytest.approx(0.03 * second.joule_w, rel=1e-12)
    assert abs(e.imbalance_j) < 1e-7 * (e.joule_j + e.convective_loss_j)
    assert second.T.max() > first.T.max() > 310.15


def test_methods_can_alternate_on_one_solver(mesh_geom, rng):
    """A monolithic step with a new sigma must not leave a stale potential for the staggered one."""
    mesh, geom = mesh_geom
    coeffs = scene(mesh, rng)
    contact = contact_weights(mesh, (0.1, 0.05, 0.1), A_M)
    kw = {"contact": contact, "drive": ElectrodeDrive(), "rho_c": coeffs["rho_c"], "k": coeffs["k"]}
    T = np.full(mesh.n_nodes, 310.15)
    mixed = ElectroThermal(mesh, geom)
    mixed.staggered_step(T, 0.03, sigma=coeffs["sigma"], **kw)
    mixed.monolithic_step(T, 0.03, sigma=2 * coeffs["sigma"], **kw)
    after = mixed.staggered_step(T, 0.03, sigma=2 * coeffs["sigma"], **kw)
    fresh = ElectroThermal(mesh, geom).staggered_step(T, 0.03, sigma=2 * coeffs["sigma"], **kw)
    assert np.allclose(after.V, fresh.V, rtol=1e-6, atol=0)  # both solved to rtol 1e-8
    assert np.allclose(after.T, fresh.T, rtol=1e-9, atol=0)
