"""The engine runs only the effects a scene calls for, skips provably idle work, keeps energy,
and restores from a checkpoint bit for bit."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from diathermy.engine.backends import fem_of
from diathermy.engine.simulation import Simulation
from diathermy.errors import CheckpointError, SceneError
from diathermy.physics.electric import joule_heat
from diathermy.scene import AccuracyBudget, Electrode

from .scenes import tiny_scene

SOLVER_EFFECTS = ("electric", "thermal", "vaporization", "mechanics", "dissection")


@pytest.mark.parametrize(
    "effects",
    [
        ["electric"],
        ["electric", "thermal"],
        ["electric", "vaporization"],
        ["electric", "mechanics"],
        ["electric", "dissection"],
    ],
)
def test_effects_not_called_for_never_run(effects):
    sim = Simulation(tiny_scene(effects=effects))
    sim.run(20)
    closed = sim.effects
    for effect in SOLVER_EFFECTS:
        if effect not in closed:
            assert sim.calls[effect] == 0, effect
            assert effect not in sim.last_report.effects
    assert sim.calls["electric"] >= 1
    if "dissection" in closed:
        assert sim.calls["dissection"] > 0 and sim.last_report.cut_volume_m3 > 0


def test_idle_work_is_skipped_with_a_reason():
    sim = Simulation(tiny_scene(electrodes=[Electrode(position_m=(0.01, 0.005), power_w=0.0)]))
    reports = sim.run(100)
    for effect in ("electric", "vaporization", "mechanics", "dissection"):
        assert sim.calls[effect] == 0, effect
    rep = reports[-1]
    assert "no active electrode" in rep.effects["electric"].reason
    assert "saturation" in rep.effects["vaporization"].reason
    assert "p0" in rep.effects["mechanics"].reason
    assert "kappa" in rep.effects["dissection"].reason
    # zero power for 100 steps: nothing but cooling towards ambient changes
    t = sim.tissue
    assert np.all(sim.state["pressure"] == t.p_atm_pa)
    assert not sim.state["displacement"].any() and not sim.state["removed"].any()
    assert np.array_equal(sim.state["level_set"], Simulation(sim.scene).state["level_set"])
    T = sim.state["temperature"]
    assert T.min() >= t.t_ambient_k - 1e-9 and T.max() <= t.t_initial_k + 1e-9


def test_fixed_electrode_reuses_potential_until_the_cut():
    sim = Simulation(tiny_scene(effects=["electric", "thermal"]))
    sim.run(10)
    assert sim.calls["electric"] == 10
    assert sim.potential.solver.krylov.n_solves == 1  # one unit-current solve, reused 9 times
    assert "reused" in sim.last_report.effects["electric"].reason


def test_reused_potential_scales_its_joule_heat_and_load():
    """While the unit field is reused its Joule heat and nodal load are scaled by I^2, not
    recomputed: the same q as sigma |grad V|^2 of the step's V, through a change of drive."""
    scene = tiny_scene(
        effects=["electric", "thermal"],
        electrodes=[Electrode(name="e", position_m=(0.01, 0.005), power_w=30.0, drive="power")],
    )
    sim = Simulation(scene)
    sim.run(3)
    sim.set_electrode("e", power_w=12.0)
    for _ in range(2):
        joule_before = sim.last_report.energy["joule_in"]
        rep = sim.step()
        # the heat step took the handed-on nodal load: the ledger books the set power
        assert rep.energy["joule_in"] - joule_before == pytest.approx(12.0 * scene.dt_s, rel=1e-9)
        assert "reused" in rep.effects["electric"].reason
        V, q = sim.state["potential"], sim.state["joule_heat"]
        sigma = np.full(sim.ctx.disc.n_tets, sim.tissue.sigma_s_per_m)
        assert np.abs(q - joule_heat(sim.ctx.disc.grid, sigma, V)).max() <= 1e-12 * q.max()
        load = sim.ctx.heat.hmesh.joule_load(q)
        assert load.sum() == pytest.approx(12.0, rel=1e-9)  # the set power, to round-off
    assert sim.potential.solver.krylov.n_solves == 1


def test_coagulation_matches_full_scene_until_first_vaporization():
    full = Simulation(tiny_scene())
    coag = Simulation(tiny_scene(effects=["electric", "thermal"]))
    for _ in range(30):
        rf = full.step()
        if rf.effects["vaporization"].ran:
            break
        coag.step()
        assert np.array_equal(full.state["temperature"], coag.state["temperature"])
    else:
        pytest.fail("the tiny scene never vaporised")
    assert full.step_index > 2


def test_energy_balance_of_a_heated_run_closes():
    sim = Simulation(tiny_scene(effects=["electric", "vaporization"]))
    reports = sim.run(40)
    e = reports[-1].energy
    assert e["latent_stored"] > 0  # water did boil
    assert abs(e["imbalance"]) <= 1e-3 * e["joule_in"]
    stored = e["sensible_stored"] + e["latent_stored"]
    assert stored == pytest.approx(e["joule_in"] - e["convective_out"], rel=1e-6)


def draped(**kw) -> Electrode:
    return Electrode(position_m=(0.01, 0.005), power_w=30.0, contact="draped", **kw)


@pytest.mark.parametrize("contact", ["flat", "draped"])
def test_cut_happens_and_electrode_follows_crater(contact):
    sim = Simulation(tiny_scene(electrodes=[draped().model_copy(update={"contact": contact})]))
    reports = sim.run(40)
    cut = [r.cut_volume_m3 for r in reports]
    assert cut[-1] > 0 and all(b >= a for a, b in zip(cut, cut[1:], strict=False))  # irreversible
    depth = reports[-1].crater_depth_m
    assert 0 < depth < 0.01
    (key,) = sim.ctx.contacts.entries
    assert key[2] < sim.ctx.top_z  # the contact disk sits on the crater floor, not the old top
    if contact == "draped":  # each point on the healthy surface under it, none above the top
        heights = np.asarray(key[4:])
        assert heights.size == 16 * 64 and np.nanmax(heights) <= sim.ctx.top_z
        assert np.nanmin(heights) < sim.ctx.top_z and np.all(heights[np.isfinite(heights)] > 0)


def test_the_reported_displacement_is_the_tissues():
    """Once something is cut, the step's max |u| is over the nodes of tets not removed: the
    crater's nodes, held by the ersatz material alone, move by what its solve leaves."""
    early = Simulation(tiny_scene())
    before = early.run(8)[-1]
    assert not early.state["removed"].any() and before.max_displacement_m > 0
    # nothing cut yet: every node counts
    assert before.max_displacement_m == np.linalg.norm(early.state["displacement"], axis=1).max()
    sim = Simulation(tiny_scene(dt_s=1.0))
    rep = sim.run(4)[-1]
    removed = sim.state["removed"]
    assert removed.any()
    u = np.linalg.norm(sim.state["displacement"], axis=1)
    tissue = np.zeros(u.size, dtype=bool)
    tissue[sim.disc.mesh.tets[~removed].ravel()] = True
    assert rep.max_displacement_m == u[tissue].max()
    assert u[~tissue].max() > 2 * rep.max_displacement_m  # the void moves more (5.3 mm vs 1.1)


@pytest.mark.parametrize("contact", ["flat", "draped"])
def test_checkpoint_restore_continues_bit_for_bit(tmp_path, contact):
    sim = Simulation(tiny_scene(electrodes=[draped().model_copy(update={"contact": contact})]))
    sim.run(18)  # past boiling and into the cut
    # both AMG hierarchies are kept from before the cut: the restore must rebuild those
    fem = fem_of(sim.ctx.mechanics)
    assert fem is not None and fem.krylov.stale and sim.ctx.potential.solver.krylov.stale
    sim.set_electrode("active", power_w=25.0)
    path = sim.save_checkpoint(tmp_path / "c.h5")
    sim.run(8)
    back = Simulation.load_checkpoint(path)
    assert back.step_index == 18 and back.time_s == pytest.approx(18 * 0.03)
    back.run(8)
    for name, arr in sim.state.arrays.items():
        assert np.array_equal(arr, back.state.arrays[name]), name
    assert sim.state.energy == back.state.energy


def test_checkpoint_continues_under_a_changed_scene(tmp_path):
    """Settings may change on load (the real-time benchmark compares modes from one state): the
    state is the saved one, the scene the mapped one; a different grid is refused."""
    sim = Simulation(tiny_scene(effects=["electric", "thermal"]))
    sim.run(5)
    path = sim.save_checkpoint(tmp_path / "c.h5")

    def full(scene):
        data = scene.model_dump()
        data["solver"]["incremental"] = False
        return type(scene).model_validate(data)

    back = Simulation.load_checkpoint(path, scene=full)
    assert back.scene.solver.incremental is False and back.step_index == 5
    for name, arr in sim.state.arrays.items():
        assert np.array_equal(arr, back.state.arrays[name]), name
    other = lambda scene: scene.model_copy(update={"grid": (5, 5, 9)})  # noqa: E731
    with pytest.raises(CheckpointError, match="do not match"):
        Simulation.load_checkpoint(path, scene=other)


def test_bad_checkpoints_get_clear_errors(tmp_path):
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"\x89HDF not really")
    with pytest.raises(CheckpointError, match="not a readable HDF5"):
        Simulation.load_checkpoint(junk)
    with h5py.File(tmp_path / "foreign.h5", "w") as f:
        f["x"] = 1
    with pytest.raises(CheckpointError, match="not a diathermy checkpoint"):
        Simulation.load_checkpoint(tmp_path / "foreign.h5")
    good = Simulation(tiny_scene(effects=["thermal"])).save_checkpoint(tmp_path / "g.h5")
    with h5py.File(good, "a") as f:
        del f["state/temperature"]
        f["state/temperature"] = np.zeros(3)
    with pytest.raises(CheckpointError, match="do not match"):
        Simulation.load_checkpoint(good)
    with h5py.File(good, "a") as f:
        del f.attrs["scene"]
    with pytest.raises(CheckpointError, match="incomplete or corrupt"):
        Simulation.load_checkpoint(good)


def test_set_electrode_validates():
    sim = Simulation(tiny_scene(effects=["electric"]))
    with pytest.raises(SceneError, match="unknown electrode"):
        sim.set_electrode("nope", power_w=1.0)
    with pytest.raises(SceneError, match="position_m"):
        sim.set_electrode("active", position_m=(1.0, 0.0))
    with pytest.raises(SceneError, match="power_w"):
        sim.set_electrode("active", power_w=float("nan"))
    sim.set_electrode("active", power_w=12.0)
    assert sim.step().delivered_power_w == pytest.approx(12.0, rel=1e-9)
    sim.set_electrode("active", active=False)
    assert sim.step().delivered_power_w == 0.0


def test_fields_and_surface():
    sim = Simulation(tiny_scene())
    sim.run(20)
    assert sim.field("temperature").shape == (9, 9, 17)
    assert sim.field("displacement").shape == (9, 9, 17, 3)
    assert sim.field("strain_energy").shape == (sim.disc.n_tets,)
    with pytest.raises(SceneError, match="unknown field"):
        sim.field("bogus")
    verts, faces = sim.cut_surface()
    assert verts.shape[1] == 3 and faces.shape[1] == 3 and faces.shape[0] > 0


def test_monolithic_coupling_matches_staggered():
    """The paper's block-GMRES solve gives the staggered result to solver tolerance."""
    from diathermy.scene import SolverConfig

    stag = Simulation(tiny_scene(effects=["electric", "thermal"]))
    mono = Simulation(
        tiny_scene(effects=["electric", "thermal"], solver=SolverConfig(coupling="monolithic"))
    )
    for _ in range(6):
        rs, rm = stag.step(), mono.step()
        assert rm.effects["thermal"].extra["coupling"] == "monolithic"
        assert rm.delivered_power_w == pytest.approx(rs.delivered_power_w, rel=1e-6)
    dT = stag.state["temperature"] - stag.tissue.t_initial_k
    assert np.max(np.abs(mono.state["temperature"] - stag.state["temperature"])) <= 1e-6 * dT.max()
    assert abs(mono.last_report.energy["imbalance"]) <= 1e-6 * mono.last_report.energy["joule_in"]


def test_policy_is_the_callers():
    """An unresolved accuracy budget and a registry model name without a registry are refused
    with errors naming the field: the engine reads no report, registry or variable itself."""
    budgeted = tiny_scene(accuracy_budget=AccuracyBudget(max_strain_energy_error=0.02))
    with pytest.raises(SceneError, match="accuracy_budget"):
        Simulation(budgeted)
    named = tiny_scene(mechanics={"backend": "cnn", "model": "some-registry-name:3"})
    with pytest.raises(SceneError, match=r"mechanics\.model.*no model registry"):
        Simulation(named)


def test_nonlocal_cut_driver_runs_through_the_engine():
    """level_set.nonlocal_length_m reaches the dissection effect: the averaged driver cuts, and
    not what the local law cuts (the mean over 0.5 mm is not the nodal value)."""
    from diathermy.scene import LevelSetConfig

    local = Simulation(tiny_scene()).run(30)[-1].cut_volume_m3
    averaged = Simulation(tiny_scene(level_set=LevelSetConfig(nonlocal_length_m=5e-4)))
    cut = averaged.run(30)[-1].cut_volume_m3
    assert cut > 0 and abs(cut / local - 1) > 0.01
    assert averaged.scene.level_set.law(7e4).nonlocal_length_m == 5e-4


def test_a_generator_voltage_limit_holds_the_electrode_and_lowers_the_power():
    """30 W needs some voltage V30 on the tiny block; a limit of half that holds every step at
    it (delivered P = V_max I, a quarter of the set power at first) and says so; a limit above
    what the run ever needs leaves it bit for bit as without one, cut included."""
    free = Simulation(tiny_scene(steps=20))
    free_reports = free.run(20)
    volts = [r.effects["electric"].extra["voltage_v"] for r in free_reports]
    assert all(not r.effects["electric"].extra["voltage_limited"] for r in free_reports)
    v_max = 0.5 * volts[0]
    held = Simulation(tiny_scene(electrodes=[Electrode(position_m=(0.01, 0.005), power_w=30.0,
                                                       max_voltage_v=v_max)]))  # fmt: skip
    reports = held.run(8)
    assert reports[0].delivered_power_w == pytest.approx(0.25 * 30.0, rel=1e-9)
    for r in reports:
        extra = r.effects["electric"].extra
        assert extra["voltage_limited"] and extra["voltage_v"] == pytest.approx(v_max, rel=1e-9)
        assert r.delivered_power_w == pytest.approx(v_max * extra["current_a"], rel=1e-9)
    loose = Simulation(tiny_scene(steps=20, electrodes=[
        Electrode(position_m=(0.01, 0.005), power_w=30.0, max_voltage_v=1.01 * max(volts))
    ]))  # fmt: skip
    loose.run(20)
    assert free_reports[-1].cut_volume_m3 > 0
    for name in ("temperature", "level_set", "displacement"):
        assert np.array_equal(loose.state[name], free.state[name]), name


@pytest.mark.parametrize("v", [0, -1, "nan", None])
def test_scene_voltage_limit_is_validated(v):
    from pydantic import ValidationError

    if v is None:
        assert Electrode(max_voltage_v=None).max_voltage_v is None
        return
    with pytest.raises(ValidationError, match="max_voltage_v"):
        Electrode(max_voltage_v=float(v))


def test_a_voltage_limit_set_at_run_time_holds_lifts_and_survives_a_checkpoint(tmp_path):
    """set_electrode(max_voltage_v=V) limits from the next step, 0 lifts the scene's own limit,
    and a checkpoint keeps the run-time limit (the restored run repeats the original)."""
    sim = Simulation(tiny_scene(electrodes=[Electrode(position_m=(0.01, 0.005), power_w=30.0,
                                                      max_voltage_v=1e3)]))  # fmt: skip
    need = sim.step().effects["electric"].extra["voltage_v"]
    sim.set_electrode("active", max_voltage_v=0.5 * need)
    held = sim.step()
    assert held.effects["electric"].extra["voltage_limited"]
    current = held.effects["electric"].extra["current_a"]
    assert held.delivered_power_w == pytest.approx(0.5 * need * current, rel=1e-9)
    assert held.delivered_power_w < 0.3 * 30.0  # about a quarter: R barely moved in one step
    sim.save_checkpoint(tmp_path / "c.h5")
    again = Simulation.load_checkpoint(tmp_path / "c.h5")
    a, b = sim.step(), again.step()
    assert b.effects["electric"].extra["voltage_limited"]
    assert a.delivered_power_w == b.delivered_power_w
    assert np.array_equal(sim.state["temperature"], again.state["temperature"])
    sim.set_electrode("active", max_voltage_v=0.0)  # lifts the scene's 1 kV too
    assert sim.step().delivered_power_w == pytest.approx(30.0, rel=1e-12)
    with pytest.raises(SceneError, match="max_voltage_v"):
        sim.set_electrode("active", max_voltage_v=-1.0)
