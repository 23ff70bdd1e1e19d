"""A scene that leaves an effect out says when that effect would have acted: each step report's
``left_out_effects`` turns on exactly at the step where the scene with the effect first departs
from it (until then the two runs are the same state), and never in a scene that has them all."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from diathermy.engine.left_out import left_out_acting
from diathermy.engine.simulation import Simulation
from diathermy.physics.materials import Tissue
from diathermy.scene.models import EFFECTS, close_effects

from .scenes import tiny_scene


def paired(effects: list[str], steps: int) -> list[tuple[object, object, bool]]:
    """(report with every effect, report of ``effects``, same state before the step) per step."""
    full, part = Simulation(tiny_scene()), Simulation(tiny_scene(effects=effects))
    out = []
    for _ in range(steps):
        same = np.array_equal(full.state["temperature"], part.state["temperature"])
        out.append((full.step(), part.step(), same))
    return out


def first(flags: list[bool]) -> int:
    return flags.index(True)


def test_coagulation_flags_vaporization_at_the_step_the_full_scene_first_boils():
    pairs = paired(["electric", "thermal"], 12)
    flagged = ["vaporization" in p.left_out_effects for _, p, _ in pairs]
    boiled = [f.max_pressure_pa > Tissue().p_atm_pa for f, _, _ in pairs]
    k = first(flagged)
    assert k == first(boiled) and k > 0  # the tiny scene boils by step ~5, not at once
    assert all(same for _, _, same in pairs[: k + 1])  # up to that step the runs are one state
    assert all(flagged[k:])  # and it stays on while the tissue is past boiling
    assert "passes boiling (373.15 K)" in pairs[k][1].left_out_effects["vaporization"]
    assert set(pairs[-1][1].left_out_effects) == {"vaporization"}


def test_vapor_without_mechanics_flags_mechanics_once_the_pressure_rises():
    pairs = paired(["electric", "vaporization"], 12)
    flagged = ["mechanics" in p.left_out_effects for _, p, _ in pairs]
    pressed = [f.ran("mechanics") for f, _, _ in pairs]
    assert first(flagged) == first(pressed) > 0
    assert all(same for _, _, same in pairs[: first(flagged) + 1])
    assert "kPa" in pairs[-1][1].left_out_effects["mechanics"]


def test_mechanics_without_dissection_flags_it_at_the_step_the_full_scene_cuts():
    pairs = paired(["electric", "mechanics"], 30)
    flagged = ["dissection" in p.left_out_effects for _, p, _ in pairs]
    cut = [f.cut_volume_m3 > 0 for f, _, _ in pairs]
    assert any(cut)
    assert first(flagged) == first(cut) > 0
    assert all(same for _, _, same in pairs[: first(flagged) + 1])
    assert "kappa" in pairs[first(flagged)][1].left_out_effects["dissection"]


def test_a_scene_with_every_effect_leaves_nothing_out():
    reports = Simulation(tiny_scene(steps=25)).run(25)
    assert any(r.cut_volume_m3 > 0 for r in reports)  # it boiled, pressed and cut
    assert all(r.left_out_effects == {} for r in reports)


def test_an_electric_only_scene_says_its_joule_heat_goes_nowhere():
    (report,) = Simulation(tiny_scene(effects=["electric"])).run(1)
    assert report.left_out_effects.keys() == {"thermal"}
    assert report.left_out_effects["thermal"].startswith("30 W of Joule heat")


def test_run_summary_warns_once_per_left_out_effect(tmp_path):
    from diathermy.engine.run import run_scene

    summary = run_scene(
        tiny_scene(effects=["electric", "thermal"], steps=10), out=tmp_path / "c.h5", progress=False
    )
    (line,) = summary.warnings()
    t, why = summary.left_out["vaporization"]
    assert 0 < t < 0.3 and line.startswith("warning: tiny: the scene leaves out vaporization")
    assert f"t = {t:.2f} s" in line and why in line


@given(
    effects=st.sets(st.sampled_from(EFFECTS), min_size=1),
    t=st.floats(200.0, 5000.0),
    p=st.floats(1e3, 1e8),
    w=st.floats(0.0, 1e7),
    power=st.floats(0.0, 500.0),
)
def test_flags_follow_the_thresholds_for_any_effects_and_state(effects, t, p, w, power):
    tissue = Tissue()
    closed = close_effects(sorted(effects))
    got = left_out_acting(
        closed,
        tissue,
        max_temperature_k=t,
        max_pressure_pa=p,
        max_strain_energy_j_per_m3=w,
        delivered_power_w=power,
    )
    assert not set(got) & set(closed)  # only effects the scene leaves out
    assert ("vaporization" in got) == ("vaporization" not in closed and t > tissue.t_boil_k)
    assert ("dissection" in got) == (
        "mechanics" in closed and "dissection" not in closed and w > tissue.damage_kappa_j_per_m3
    )
    assert all(isinstance(v, str) and v for v in got.values())


@pytest.mark.parametrize("effects", [["electric", "thermal"], ["electric", "vaporization"]])
def test_run_files_keep_the_flags(tmp_path, effects):
    from diathermy.engine.run import run_scene
    from diathermy.engine.runfile import read_run

    run_scene(tiny_scene(effects=effects, steps=10), out=tmp_path / "r.h5", progress=False)
    reports = read_run(tmp_path / "r.h5")["reports"]
    assert reports[0]["left_out_effects"] == {} and reports[-1]["left_out_effects"]
