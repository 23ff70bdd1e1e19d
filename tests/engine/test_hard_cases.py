"""The hard-case suite (DESIGN.md ask 2): scenes that must stay finite, bounded and solver-clean.

Every case checks ``assert_sane`` after every step (see there for the bounds) plus what is
particular to it, under both cut rules (``level_set.removal`` threshold and fraction). Grids are
small (9x9x17 or 5x5x9) so that the file runs in CI in well under 3 minutes.
"""

from __future__ import annotations

import numpy as np
import pytest
import skfmm

from diathermy.engine.report import StepReport
from diathermy.engine.simulation import Simulation
from diathermy.physics.eos import saturation_pressure
from diathermy.physics.materials import Tissue
from diathermy.physics.topology import evaluate_topology
from diathermy.scene import Electrode, ElectrodePath
from diathermy.scene import Scene as SceneModel

from . import scenes

REMOVALS = ("threshold", "fraction")
_RULE = {"removal": "threshold"}  # the running case's cut rule


@pytest.fixture(params=REMOVALS, autouse=True)
def removal(request: pytest.FixtureRequest):  # noqa: ANN201
    """Every case under each cut rule: the scenes this module builds get it."""
    _RULE["removal"] = str(request.param)
    yield request.param
    _RULE["removal"] = "threshold"


def tiny_scene(**overrides):  # noqa: ANN003, ANN201
    """The tiny scene under the running case's cut rule."""
    return scenes.tiny_scene(level_set=dict(_RULE), **overrides)


def Scene(**fields):  # noqa: ANN003, ANN201, N802
    """``diathermy.scene.Scene`` under the running case's cut rule."""
    return SceneModel(level_set=dict(_RULE), **fields)


T_CEILING_K = 1000.0
"""A physical ceiling for tissue temperature: far above charring (~600 K), far below anything a
sane model reaches while latent heat holds boiling tissue near saturation."""

RHO_C_MAX = 3.6e6
"""J/(m^3 K), above the tissue's rho c at any vapor fraction (3.51e6 at x = 0)."""

FULL = ("electric", "thermal", "vaporization", "mechanics", "dissection")
TINY_CENTRE = (0.01, 0.005)


def assert_sane(sim: Simulation, rep: StepReport) -> None:
    """The bounds every hard case keeps after every step.

    - every field finite (no NaN/Inf);
    - min(T0, T_amb) <= T <= T_CEILING_K (1000 K): no undershoot, no runaway heating;
    - p0 <= p <= p_sat(max T) <= p_sat(T_CEILING_K): the EOS never supersaturates;
    - 0 <= x <= 1 and the tissue's |u| (the report's) below the smallest block dimension;
    - the energy balance closes: |Joule in - sensible - latent - convective| <= 1e-6 Joule in,
      plus what the heat solves' tolerance allows: each leaves a residual <= rtol |M T / dt|, so
      the stored energy may be off by ~rtol sum(m T) per step (dominant only at dt ~ 1e-4 s);
    - every solve that ran reached its tolerance (electric and mechanics residuals <= rtol; an
      incremental mechanics step that stayed local: its relative residual <= the guard, or its
      energy-error estimate <= the energy tolerance; the interval's global PCG: its estimate <=
      the interval tolerance).
    """
    st, t = sim.state, sim.tissue
    for name, arr in st.arrays.items():
        if arr.dtype != bool:
            assert np.all(np.isfinite(arr)), f"step {rep.step}: {name} not finite"
    T = st["temperature"]
    assert T.min() >= min(t.t_initial_k, t.t_ambient_k) - 1e-9, rep.step
    assert T.max() <= T_CEILING_K, (rep.step, T.max())
    p = st["pressure"]
    assert p.min() >= t.p_atm_pa - 1e-9, rep.step
    p_cap = max(float(saturation_pressure(T.max(), t)), t.p_atm_pa)
    assert p.max() <= p_cap * (1 + 1e-9), (rep.step, p.max(), p_cap)
    assert p_cap <= float(saturation_pressure(T_CEILING_K, t))
    x = st["vapor_fraction"]
    assert x.min() >= 0.0 and x.max() <= 1.0, rep.step
    assert rep.max_displacement_m < min(sim.scene.block_m), (rep.step, rep.max_displacement_m)
    e = rep.energy
    heat_content = RHO_C_MAX * float(np.prod(sim.scene.block_m)) * T.max()  # J, >= sum(m T)
    solver_slack = 10 * sim.scene.solver.thermal_rtol * heat_content * rep.step
    assert abs(e["imbalance"]) <= 1e-6 * e["joule_in"] + solver_slack, (rep.step, e)
    el = rep.effects.get("electric")
    if el is not None and el.ran:  # the energy guard's estimate, or a solve to rtol
        if el.extra["mode"] == "local":
            assert el.extra["energy_estimate"] <= el.extra["energy_tolerance"], rep.step
        else:
            assert el.extra["residual"] <= sim.scene.solver.electric_rtol * 1.01, rep.step
    mech = rep.effects.get("mechanics")
    if mech is not None and mech.ran:  # the incremental path: its guard; a full solve: rtol
        polished = mech.extra["mode"] == "local" or "whole block" in mech.extra.get("why", "")
        if "energy_estimate" in mech.extra and polished:  # polished, or the interval's PCG
            assert mech.extra["energy_estimate"] <= mech.extra["energy_tolerance"], rep.step
        else:
            tol = mech.extra["guard_tolerance"] if mech.extra["mode"] == "local" else None
            assert mech.extra["residual"] <= (tol or sim.scene.mechanics.rtol * 1.01), rep.step


def run_sane(sim: Simulation, n: int) -> list[StepReport]:
    reports = []
    for _ in range(n):
        rep = sim.step()
        assert_sane(sim, rep)
        reports.append(rep)
    return reports


def in_contact(rep: StepReport) -> bool:
    return "no active electrode" not in rep.effects["electric"].reason


@pytest.mark.parametrize("where", [(0.0, 0.005), (0.0, 0.0)], ids=["edge", "corner"])
def test_electrode_on_an_edge_and_on_a_corner(where):
    """Half (edge) or a quarter (corner) of the contact disk lies on the block: the set 30 W is
    delivered while in contact, the cut grows irreversibly, and once it reaches the return
    electrode the contact ends (power 0) instead of dividing by a zero resistance."""
    sim = Simulation(tiny_scene(electrodes=[Electrode(position_m=where, power_w=30.0)]))
    reports = run_sane(sim, 1)
    (contact,) = sim.ctx.contacts.entries.values()
    share = 0.5 if where[1] > 0 else 0.25  # the disk's part on the block
    assert contact.area_m2 == pytest.approx(share * np.pi * 1.17e-3**2, rel=1e-9)
    reports += run_sane(sim, 39)
    for rep in reports:
        assert rep.delivered_power_w == pytest.approx(30.0 if in_contact(rep) else 0.0, rel=1e-9)
    cut = [r.cut_volume_m3 for r in reports]
    assert cut[-1] > 0 and all(b >= a for a, b in zip(cut, cut[1:], strict=False))


def test_four_times_the_default_power():
    """200 W (4x the 50 W setting) on a 2 cm block: boils, cuts through to the return electrode
    within a second, and every bound holds; the contact then ends (power 0, reason given)."""
    sim = Simulation(tiny_scene(electrodes=[Electrode(position_m=TINY_CENTRE, power_w=200.0)]))
    reports = run_sane(sim, 30)
    assert max(r.max_temperature_k for r in reports) > sim.tissue.t_boil_k
    assert reports[-1].crater_depth_m > 0
    for rep in reports:
        assert rep.delivered_power_w == pytest.approx(200.0 if in_contact(rep) else 0.0, rel=1e-9)
    if not in_contact(reports[-1]):
        assert "return electrode" in reports[-1].effects["electric"].reason
        assert reports[-1].crater_depth_m == pytest.approx(0.01)


@pytest.mark.parametrize("effects", [["electric", "thermal"], list(FULL)], ids=["coag", "full"])
def test_a_path_that_leaves_the_block(effects):
    """The electrode cuts in place for 0.6 s, then runs off the +y face at 20 mm/s: the set 30 W
    is delivered while any of the disk touches the block, 0 W once it is off, and no step fails
    (the crater lookup of a centre off the block used to raise)."""
    a = 1.17e-3
    path = ElectrodePath(waypoints_m=[TINY_CENTRE, (0.01, 0.03)], speed_m_per_s=0.02, start_s=0.6)
    el = Electrode(position_m=TINY_CENTRE, power_w=30.0, path=path)
    sim = Simulation(tiny_scene(electrodes=[el], effects=effects))
    reports = run_sane(sim, 40)
    for rep in reports:
        y = 0.005 + max(0.0, 0.02 * (rep.time_s - 0.015 - 0.6))  # the pose at mid-step
        if y < 0.01 + a - 1e-4:
            assert rep.delivered_power_w == pytest.approx(30.0, rel=1e-9), rep.step
        elif y > 0.01 + a + 1e-4:
            assert rep.delivered_power_w == 0.0, rep.step
            assert "no active electrode" in rep.effects["electric"].reason
    assert reports[-1].delivered_power_w == 0.0
    if "dissection" in effects:
        assert reports[-1].cut_volume_m3 > 0


@pytest.mark.parametrize("dt", [1e-4, 1e-3, 0.03, 0.3, 1.0])
def test_time_steps_from_a_tenth_of_a_millisecond_to_a_second(dt):
    """All effects at dt from 1e-4 s to 1 s (33x the default): every bound holds. At 1 s the
    front sweeps millimetres per step; its level set stays finite (it fell to -1e81 m before
    the ghost-slope cap) and never rises anywhere (irreversible), and the crater stays within
    the block's height."""
    sim = Simulation(tiny_scene(dt_s=dt))
    phi0 = sim.state["level_set"].copy()
    n = 10 if dt >= 0.3 else 20
    reports = run_sane(sim, n)
    assert reports[-1].energy["joule_in"] == pytest.approx(
        30.0 * sum(r.delivered_power_w > 0 for r in reports) * dt, rel=1e-6
    )
    assert np.all(sim.state["level_set"] <= phi0)
    assert all(0 <= r.crater_depth_m <= sim.scene.block_m[2] + 1e-12 for r in reports)


def test_ten_second_steps_of_the_heat_equation():
    """Electric + thermal at dt = 10 s (330x the default) over 300 s: no undershoot below
    T_amb, energy closes to 1e-6, and the result agrees with 1 s steps: the stored energy (mean
    temperature) to 1 % and the hottest node to 5 % of its rise."""
    scene = tiny_scene(
        effects=["electric", "thermal"],
        electrodes=[Electrode(position_m=TINY_CENTRE, power_w=2.0)],
    )
    big = Simulation(scene.model_copy(update={"dt_s": 10.0}))
    run_sane(big, 30)
    fine = Simulation(scene.model_copy(update={"dt_s": 1.0}))
    run_sane(fine, 300)
    eb, ef = big.last_report.energy, fine.last_report.energy
    assert eb["joule_in"] == pytest.approx(ef["joule_in"], rel=1e-9)
    assert eb["sensible_stored"] == pytest.approx(ef["sensible_stored"], rel=1e-2)
    rise_big = big.state["temperature"].max() - big.tissue.t_ambient_k
    rise_fine = fine.state["temperature"].max() - fine.tissue.t_ambient_k
    assert rise_big == pytest.approx(rise_fine, rel=5e-2)


def test_cells_larger_than_the_electrode():
    """The default 20 x 10 x 10 cm block on 5x5x9 nodes (25 mm cells, a 1.17 mm electrode): the
    whole contact area is still loaded (current conserved by quadrature), the set 50 W is
    delivered, and 300 steps of all effects stay bounded."""
    sim = Simulation(Scene(grid=(5, 5, 9), steps=300))
    reports = run_sane(sim, 300)
    (contact,) = sim.ctx.contacts.entries.values()
    assert contact.area_m2 == pytest.approx(np.pi * 1.17e-3**2, rel=1e-12)
    assert all(r.delivered_power_w == pytest.approx(50.0, rel=1e-9) for r in reports)
    assert reports[-1].energy["joule_in"] == pytest.approx(50.0 * 300 * 0.03, rel=1e-9)


def test_nearly_incompressible_tissue():
    """nu = 0.49 (K = 4.5 MPa, 10x the default): the mechanics converges to its tolerance
    every step, |u| stays below the block size, and the scene still boils and cuts."""
    sim = Simulation(tiny_scene(material=Tissue(poisson_ratio=0.49)))
    reports = run_sane(sim, 40)
    assert sim.calls["mechanics"] > 0 and sim.calls["dissection"] > 0
    assert reports[-1].cut_volume_m3 > 0


def cut_out_a_fragment(sim: Simulation) -> np.ndarray:
    """Put a cut into ``sim`` that frees a bar 5 mm long (x), 3.75 mm high, across the full
    width (y) of the tiny block: a 2.5 mm wall on each side and a 2.5 mm floor under it are
    removed. Returns the mask of the fragment's tets (loose)."""
    g = sim.grid
    x, _, z = g.axes()
    X, Z = x[None, None, :], z[:, None, None]
    cut = (X >= 0.005) & (X <= 0.015) & (Z >= 0.00375)
    bar = (X >= 0.0075) & (X <= 0.0125) & (Z >= 0.00625)
    removed = np.broadcast_to(cut & ~bar, g.shape)
    dx, dy, dz = g.spacing_m
    phi = np.asarray(skfmm.distance(np.where(removed, -1.0, 1.0), dx=(dz, dy, dx)))
    sim.state["level_set"] = phi.ravel().copy()
    topo = evaluate_topology(sim.state["level_set"], sim.disc.mesh, sim.disc.geom.volumes)
    sim.topology = topo
    sim.state["removed"] = topo.removed | topo.loose
    return topo.loose


def test_a_cut_that_frees_a_fragment():
    """A cut across the full width frees a bar with the electrode on top of it: the bar is
    reported loose (dissection's ``loose_tets``) and removed, the electrode drops onto the
    healthy floor below it (it used to keep heating the floating bar), the mechanics stays
    non-singular and converged, and the run continues until the cut reaches the return
    electrode (contact ends), all without a solver error."""
    sim = Simulation(tiny_scene(electrodes=[Electrode(position_m=TINY_CENTRE, power_w=30.0)]))
    loose = cut_out_a_fragment(sim)
    assert loose.sum() > 100
    reports = run_sane(sim, 1)
    ((_, _, z_contact, _),) = sim.ctx.contacts.entries  # on the floor under the bar, not on its top
    assert 0.0 < z_contact <= 0.00375 + 1e-9
    assert reports[0].delivered_power_w == pytest.approx(30.0, rel=1e-9)
    reports += run_sane(sim, 39)
    diss = [r.effects["dissection"] for r in reports if r.effects["dissection"].ran]
    assert diss and all(d.extra["loose_tets"] >= loose.sum() for d in diss)
    assert sim.state["removed"][loose].all()
    assert sim.calls["mechanics"] > 0
    # the fragment carries no strain energy: it is ersatz material, cut off from the load
    assert sim.state["strain_energy"][loose].max() <= 1e-3 * sim.tissue.damage_kappa_j_per_m3


def on_off_scene(schedule: list[tuple[float, float]] | None) -> Scene:
    """Electric + thermal, 0.5 W on the tiny block at 5x5x9 nodes, 1 s steps."""
    return tiny_scene(
        grid=(5, 5, 9),
        dt_s=1.0,
        effects=["electric", "thermal"],
        electrodes=[Electrode(position_m=TINY_CENTRE, power_w=0.5, schedule_s=schedule)],
    )


def test_two_thousand_steps_of_on_off_activation():
    """100 cycles of 10 s on / 10 s off (2,000 steps): exactly P x on-time goes in (no drift),
    the energy balance closes to 1e-6 of it, the cycle-to-cycle change of the temperature
    shrinks geometrically towards a periodic state (last < 1e-2 of first, no accumulation), and
    the temperature stays below the continuously-on run everywhere (linear, monotone scheme)."""
    schedule = [(20.0 * c, 20.0 * c + 10.0) for c in range(100)]
    sim = Simulation(on_off_scene(schedule))
    ends = []
    t_max = sim.state["temperature"].copy()
    cont = Simulation(on_off_scene(None))
    for c in range(100):
        for _ in range(20):
            rep = sim.step()
            cont.step()
            t_max = np.maximum(t_max, sim.state["temperature"])
        assert_sane(sim, rep)
        assert np.all(sim.state["temperature"] <= cont.state["temperature"] + 1e-9), c
        ends.append(sim.state["temperature"].copy())
    e = sim.last_report.energy
    assert e["joule_in"] == pytest.approx(0.5 * 1000.0, rel=1e-9)
    inc = [float(np.abs(b - a).max()) for a, b in zip(ends, ends[1:], strict=False)]
    assert inc[-1] < 1e-2 * inc[0]
    assert all(b <= a * (1 + 1e-6) + 1e-9 for a, b in zip(inc[5:], inc[6:], strict=False))
    assert t_max.max() < cont.state["temperature"].max() + 1e-9
    assert sim.potential.solver.krylov.n_solves == 1  # one unit-current solve, rescaled


def test_zero_power_for_100_steps_after_heating():
    """Heat to just below boiling, then 100 steps at 0 W: only the temperature changes. The
    maximum never rises, the minimum stays at or above T_amb, no solver runs, Joule in is frozen,
    and pressure, vapor, displacement, level set and the cut are bitwise unchanged."""
    sim = Simulation(tiny_scene())
    run_sane(sim, 3)
    assert sim.state["temperature"].max() < sim.tissue.t_boil_k
    frozen = {k: v.copy() for k, v in sim.state.arrays.items() if k != "temperature"}
    calls = dict(sim.calls)
    joule = sim.state.energy.joule_in
    sim.set_electrode("active", power_w=0.0)
    prev_max = sim.state["temperature"].max()
    for _ in range(100):
        rep = sim.step()
        assert_sane(sim, rep)
        assert rep.delivered_power_w == 0.0
        T = sim.state["temperature"]
        assert T.max() <= prev_max + 1e-12
        prev_max = T.max()
    for k, v in frozen.items():
        if k in ("potential", "joule_heat"):
            assert not sim.state[k].any(), k
        else:
            assert np.array_equal(sim.state[k], v), k
    assert {k: sim.calls[k] for k in calls if k != "thermal"} == {
        k: v for k, v in calls.items() if k != "thermal"
    }
    assert sim.state.energy.joule_in == joule
    assert sim.state["temperature"].min() >= sim.tissue.t_ambient_k
