"""A tiny run of benchmarks/realtime.py: warm-up to the cut, the modes in lockstep, the errors
against the full mode, and the results table and plot."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from tests.benchmarks.loading import load_benchmark
from tests.engine.scenes import tiny_scene


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    return load_benchmark("realtime")


@pytest.fixture(scope="module")
def report() -> ModuleType:
    return load_benchmark("realtime_report")


def test_tiny_run_writes_its_table(bench: ModuleType, report: ModuleType, tmp_path: Path) -> None:
    scene = tiny_scene()
    # no model for a 9x9x17 grid; persistence wherever there is mechanics
    assert bench.modes_for(scene) == ["full", "incremental", "persistence"]
    assert bench.modes_for(bench.scene_on("coagulation", "uniform")) == ["full", "incremental"]
    assert bench.modes_for(scene, tight=True)[-1] == bench.TIGHT_MODE
    loose = f"{bench.TOLERANCE_MODE}0.01"
    assert bench.modes_for(scene, tolerances=(1e-2,))[-1] == loose
    loose_electric = "solver.electric_energy_tolerance=1e-4, mechanics.full_every=3"
    settings = f"{bench.SETTINGS_MODE}{loose_electric}"
    assert bench.modes_for(scene, variants=(loose_electric,))[-1] == settings
    run = bench.measure(
        scene,
        tmp_path / "tiny.h5",
        warmup=40,
        steps=4,
        tight=True,
        tolerances=(1e-2,),
        variants=(loose_electric,),
    )
    assert run["first_cut"] is not None and (tmp_path / "tiny.json").exists()
    rec = run["rec"]
    assert rec["full"]["se_err"] == [0.0] * 4 and rec["full"]["local"] == [0.0] * 4
    for mode in ("incremental", bench.TIGHT_MODE, loose, settings):
        assert max(rec[mode]["se_err"]) <= 0.01 and max(rec[mode]["dT_k"]) <= 0.1
    # the baseline solves nothing once it has a displacement, and the incremental mode corrects it
    assert rec["persistence"]["local"] == [1.0] * 4
    assert max(rec["persistence"]["se_err"]) > max(rec["incremental"]["se_err"])
    sim = bench.load_mode(tmp_path / "tiny.h5", loose)
    assert sim.scene.mechanics.energy_tolerance == 1e-2
    sim = bench.load_mode(tmp_path / "tiny.h5", settings)  # both sections set, the rest kept
    assert sim.scene.solver.electric_energy_tolerance == 1e-4 and sim.scene.solver.incremental
    assert sim.scene.mechanics.full_every == 3
    assert sim.scene.mechanics.energy_tolerance == scene.mechanics.energy_tolerance
    tight = f"{bench.SETTINGS_MODE}solver.incremental=false, mechanics.rtol=1e-8"
    sim = bench.load_mode(tmp_path / "tiny.h5", tight)  # a full mode at a tighter tolerance
    assert not sim.scene.solver.incremental and sim.scene.mechanics.rtol == 1e-8
    assert rec["full"]["cut_m3"][-1] > 0 and all(t > 0 for t in rec["full"]["mechanics"])
    # the cached checkpoint is reused, with its first-cut step
    assert bench.warm_up(scene, tmp_path / "tiny.h5", 40)[1] == run["first_cut"]
    # ... but not for a scene with other settings: a checkpoint carries its scene's
    data = scene.model_dump()
    data["mechanics"]["energy_tolerance"] = 5e-3
    other = type(scene).model_validate(data)
    mtime = (tmp_path / "tiny.h5").stat().st_mtime_ns
    bench.warm_up(other, tmp_path / "tiny.h5", 40)
    assert (tmp_path / "tiny.h5").stat().st_mtime_ns != mtime
    assert json.loads((tmp_path / "tiny.json").read_text())["scene"] == other.model_dump_json()
    args = argparse.Namespace(
        scenes=["tiny"],
        grids=["own"],
        steps=4,
        tight=True,
        tolerances=[1e-2],
        variant=[loose_electric],
        from_start=False,
    )
    report.write_run({("tiny", "own"): run}, args, "now", out=tmp_path)
    table = (tmp_path / "realtime.md").read_text()
    assert "| tiny | 9x9x17 uniform | 1,377 |" in table and "| incremental |" in table
    assert f"| {bench.TIGHT_MODE} |" in table and "--tight" in table
    assert f"| {loose} |" in table and "--tolerances 0.01" in table
    assert f"| {settings} |" in table and f"--variant '{loose_electric}'" in table
    assert (tmp_path / "realtime.png").stat().st_size > 1000
    saved = json.loads((tmp_path / "realtime.json").read_text())
    assert saved["runs"][0]["modes"]["full"]["cut_m3"] == rec["full"]["cut_m3"]
    assert (tmp_path / "realtime_errors.png").stat().st_size > 1000
    runs, command, started, load = report.read_run(tmp_path)  # 'report': the same table again
    assert started == "now" and "--variant" in command and len(load) == 3
    (tmp_path / "realtime.md").unlink()
    report.write_run(runs, command, started, tmp_path, load)
    assert (tmp_path / "realtime.md").read_text() == table


def test_each_scene_and_grid_runs_in_a_process_of_its_own(bench: ModuleType) -> None:
    """A run of several (scene, grid) pairs hands each to a child with the same settings."""
    argv = ["run", "--scenes", "default", "fixed-electrode", "--steps", "5", "--warmup", "7"]
    argv += ["--from-start", "--tight", "--tolerances", "0.01", "3e-3"]
    argv += ["--variant", "mechanics.full_every=3", "--variant", "solver.incremental=false"]
    a = bench.parser().parse_args(argv)
    child = bench.parser().parse_args(bench.run_args(a, "fixed-electrode", "uniform", Path("x")))
    assert child.scenes == ["fixed-electrode"] and child.grids == ["uniform"]
    assert child.out == Path("x")
    for key in ("steps", "warmup", "from_start", "tight", "tolerances", "variant"):
        assert getattr(child, key) == getattr(a, key), key
    a = bench.parser().parse_args(["run", "--scenes", "default", "--from-step", "90"])
    child = bench.parser().parse_args(bench.run_args(a, "default", "own", Path("x")))
    assert child.from_step == 90 and not child.from_start
    assert bench.start_suffix(child) == "_step90" and bench.start_suffix(a) == "_step90"
    plain = bench.parser().parse_args(["run", "--scenes", "default"])
    child = bench.parser().parse_args(bench.run_args(plain, "default", "own", Path("y")))
    assert not child.from_start and not child.tight and child.tolerances == [] == child.variant
    assert child.removal == "threshold" and bench.start_suffix(child) == ""
    # the removal rule goes to the child, and to the checkpoint's name (a scene of its own)
    a = bench.parser().parse_args(["run", "--removal", "fraction", "--from-start"])
    child = bench.parser().parse_args(bench.run_args(a, "default", "own", Path("z")))
    assert child.removal == "fraction" and bench.start_suffix(child) == "_fraction_start"
    assert bench.scene_on("default", "own", "fraction").level_set.removal == "fraction"
    assert bench.scene_on("default", "uniform").level_set.removal == "threshold"


def test_the_table_names_the_removal_rule_it_ran(bench: ModuleType, report: ModuleType) -> None:
    """A run under ``--removal fraction`` says so in the command its table records."""
    a = bench.parser().parse_args(["run", "--scenes", "default", "--removal", "fraction"])
    assert report.command_line(a).endswith("--steps 8 --removal fraction")
    plain = bench.parser().parse_args(["run", "--scenes", "default"])
    assert "--removal" not in report.command_line(plain)


def test_a_negative_start_step_is_refused(
    bench: ModuleType, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr("sys.argv", ["realtime.py", "run", "--from-step", "-3"])
    with pytest.raises(SystemExit) as exc:
        bench.main()
    assert exc.value.code == 2
    assert "--from-step: a step count, not -3" in capsys.readouterr().err


def test_settings_are_parsed_or_refused(bench: ModuleType) -> None:
    assert bench.parse_settings(
        "solver.electric_energy_tolerance=1e-4, mechanics.guard=energy"
    ) == {
        "solver": {"electric_energy_tolerance": 1e-4},
        "mechanics": {"guard": "energy"},
    }
    for bad in ("", "energy_tolerance=1", "thermal.rtol=1", "mechanics.energy_tolerance"):
        with pytest.raises(ValueError, match="variant"):
            bench.parse_settings(bad)


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("mechanics.window_m=0.01", "mechanics.window_m: Extra inputs are not permitted"),
        ("mechanics.window_history=40", "mechanics.window_history: Input should be less than"),
    ],
)
def test_a_setting_the_scene_refuses_stops_the_run_at_once(
    bench: ModuleType,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    spec: str,
    message: str,
) -> None:
    """An unknown key or a value out of range is a one-line usage error before any warm-up."""
    argv = ["realtime.py", "run", "--scenes", "default", "--variant", spec]
    monkeypatch.setattr("sys.argv", argv)
    with pytest.raises(SystemExit) as exc:
        bench.main()
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_whole_run_from_the_first_step(
    bench: ModuleType, report: ModuleType, tmp_path: Path
) -> None:
    """--from-start: the checkpoint holds step 0, the steps span the heating and the cut, and
    the cutting phase is the steps from the first cut on."""
    run = bench.measure(tiny_scene(), tmp_path / "start.h5", warmup=40, steps=30, from_start=True)
    rec = run["rec"]
    assert run["from_start"] and run["first_cut"] is None  # nothing stepped before the check point
    cut = rec["full"]["cut_m3"]
    assert cut[0] == 0 and cut[-1] > 0, "the tiny scene cuts within 30 steps"
    phase = report.cutting_steps(cut)
    assert phase[0] > 0 and cut[phase[0]] > 0 and cut[phase[0] - 1] == 0
    assert report.cutting_steps([0.0, 0.0]) == [0, 1]  # no cut: every step
    assert max(rec["incremental"]["se_err"]) <= 0.01 and max(rec["incremental"]["dT_k"]) <= 0.1
    args = argparse.Namespace(
        scenes=["tiny"], grids=["own"], steps=30, tight=False, tolerances=[], variant=[],
        from_start=True,
    )  # fmt: skip
    report.write_run({("tiny", "own"): run}, args, "now", out=tmp_path)
    table = (tmp_path / "realtime.md").read_text()
    assert "--from-start" in table and "from its first step" in table
    assert f"| {phase[0] + 1} |" in table  # the full mode's 'cut from' column
    assert "| - / - |" in table  # no step of the full mode is off itself
    assert rec["full"]["tets_apart"] == [0.0] * 30  # the full mode's cut is its own
    assert "| tets cut apart (steps, first) | max T error before K |" in table
    assert f"| 0 (0) | {max(rec['full']['dT_k']):.2e} |" in table
    # --from-step 12: the checkpoint after exactly 12 steps in the scene's own (incremental)
    # settings, so its incremental mode goes on as the whole run's did from there
    later = bench.measure(tiny_scene(), tmp_path / "step12.h5", warmup=40, steps=4, from_step=12)
    assert later["from_step"] == 12 and not later["from_start"]
    np.testing.assert_allclose(
        later["rec"]["incremental"]["cut_m3"], rec["incremental"]["cut_m3"][12:16], rtol=1e-12
    )
    args.from_start, args.from_step = False, 12
    report.write_run({("tiny", "own"): later}, args, "now", out=tmp_path / "later")
    table = (tmp_path / "later" / "realtime.md").read_text()
    assert "--from-step 12" in table and "from its state after 12 steps" in table
    assert report.first_over([0.0, 0.02, 0.5], 0.01) == "2" and report.first_over([0.0], 1) == "-"


def test_cut_agreement_cells_split_the_temperature_error(report: ModuleType) -> None:
    """The temperature error is split at the first step whose cut differs from the full mode's:
    the worst before it (the local solves' own error), the most tets apart and when."""
    r = {"tets_apart": [0.0, 0.0, 3.0, 1.0, 0.0], "dT_k": [0.01, 0.02, 1.5, 0.9, 5.0]}
    assert report.apart_cells(r) == " 3 (2, 3) | 2.00e-02 |"  # 5 K after the cuts agree again
    r = {"tets_apart": [0.0, 0.0], "dT_k": [0.01, 0.03]}
    assert report.apart_cells(r) == " 0 (0) | 3.00e-02 |"
    r = {"tets_apart": [2.0], "dT_k": [0.7]}
    assert report.apart_cells(r) == " 2 (1, 1) | - |"


def test_the_profile_writes_where_it_is_told(
    bench: ModuleType, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``profile --out`` writes its table there, not over the committed results."""
    committed = bench.RESULTS / "realtime_profile.md"
    before = committed.read_bytes() if committed.exists() else None
    monkeypatch.setattr(
        bench,
        "scene_on",
        lambda name, grid, removal="threshold": tiny_scene(level_set={"removal": removal}),
    )
    monkeypatch.setattr(bench, "CACHE", tmp_path / "cache")
    out = tmp_path / "out"
    args = argparse.Namespace(scenes=["default"], grids=["own"], steps=2, warmup=40, top=5, out=out)
    bench.profile(args, "now")
    text = (out / "realtime_profile.md").read_text()
    assert "| function | calls |" in text and "2 steps" in text
    assert (committed.read_bytes() if committed.exists() else None) == before
    # under --removal fraction: its own checkpoint, and the table says so
    args.removal = "fraction"
    bench.profile(args, "now")
    assert "--steps 2 --removal fraction`" in (out / "realtime_profile.md").read_text()
    cached = {p.name for p in (tmp_path / "cache").glob("*.h5")}
    assert cached == {"default_own.h5", "default_own_fraction.h5"}
