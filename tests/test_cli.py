"""The command line: simulate writes the documented run file; user errors are one line, exit 2."""

from __future__ import annotations

import json
import subprocess
import sys

from diathermy.cli import main
from diathermy.engine.runfile import read_run


def test_simulate_writes_run_file_and_vtu(tmp_path, capsys):
    scene = tmp_path / "s.json"
    scene.write_text(
        json.dumps(
            {"name": "cli", "grid": [5, 5, 9], "steps": 4, "effects": ["electric", "thermal"]}
        )
    )
    out = tmp_path / "run.h5"
    assert (
        main(["simulate", str(scene), "--out", str(out), "--vtu", str(tmp_path / "vtu"), "--quiet"])
        == 0
    )
    run = read_run(out)
    assert run["fields"]["temperature"].shape == (4, 5, 5, 9)
    assert run["fields"]["potential"].shape == (4, 5, 5, 9)
    assert run["cell_fields"]["joule_heat"].shape[0] == 4
    assert [r["step"] for r in run["reports"]] == [1, 2, 3, 4]
    assert run["reports"][0]["effects"]["electric"]["ran"]
    assert (tmp_path / "vtu" / "cli.pvd").exists() and (
        tmp_path / "vtu" / "step_00004.vtu"
    ).exists()
    assert "4 steps" in capsys.readouterr().out


def test_dissection_run_writes_removed_mask_and_cut_surface(tmp_path):
    from tests.engine.scenes import tiny_scene

    scene = tmp_path / "cut.json"
    scene.write_text(tiny_scene(steps=20).model_dump_json())
    out = tmp_path / "run.h5"
    assert (
        main(["simulate", str(scene), "--out", str(out), "--vtu", str(tmp_path / "v"), "--quiet"])
        == 0
    )
    run = read_run(out)
    removed = run["cell_fields"]["removed"]
    assert removed.shape[0] == 20 and removed[-1].sum() > 0 and not removed[0].any()
    assert (tmp_path / "v" / "cut_00020.vtu").stat().st_size > 0


def test_grid_override_and_every(tmp_path):
    out = tmp_path / "r.h5"
    assert (
        main(
            [
                "simulate",
                "coagulation",
                "--grid",
                "5x5x9",
                "--steps",
                "4",
                "--every",
                "2",
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    run = read_run(out)
    assert list(run["step"]) == [2, 4] and "thermal_damage" in run["fields"]


def test_guard_option_sets_the_scene_and_is_validated(tmp_path, capsys):
    out = tmp_path / "g.h5"
    args = ["simulate", "coagulation", "--grid", "5x5x9", "--steps", "1", "--quiet"]
    assert main([*args, "--guard", "5e-3", "--out", str(out)]) == 0
    scene = json.loads(read_run(out)["attrs"]["scene"])
    assert scene["mechanics"]["guard_tolerance"] == 5e-3
    proc = subprocess.run(
        [sys.executable, "-m", "diathermy", *args, "--guard", "-1", "--out", str(out)],
        capture_output=True, text=True,
    )  # fmt: skip
    assert proc.returncode == 2 and "guard_tolerance" in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_user_errors_are_one_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("grid: [2, 2, 2]\n")
    for args in (
        ["simulate", "no-such-scene"],
        ["simulate", str(bad)],
        ["simulate", str(tmp_path / "missing.json")],
    ):
        proc = subprocess.run(
            [sys.executable, "-m", "diathermy", *args], capture_output=True, text=True
        )
        assert proc.returncode == 2, proc.stderr
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("diathermy: error:"), proc.stderr
    proc = subprocess.run(
        [sys.executable, "-m", "diathermy", "simulate", "--grid", "3x3"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2 and "Traceback" not in proc.stderr


def test_scenes_and_schema(capsys):
    assert main(["scenes"]) == 0
    listing = capsys.readouterr().out
    assert "fixed-electrode" in listing and "moving-electrode" in listing
    assert main(["schema"]) == 0
    assert "electrodes" in json.loads(capsys.readouterr().out)["properties"]


def test_simulate_warns_when_a_left_out_effect_would_act(tmp_path, capsys):
    """Electric and thermal only at 30 W: the tissue passes boiling by step ~5, so the scene's
    missing vaporization is named on stderr, once, with when and why."""
    from tests.engine.scenes import tiny_scene

    scene = tmp_path / "c.json"
    scene.write_text(tiny_scene(effects=["electric", "thermal"], steps=10).model_dump_json())
    assert main(["simulate", str(scene), "--out", str(tmp_path / "c.h5"), "--quiet"]) == 0
    out, err = capsys.readouterr()
    assert "10 steps" in out
    (line,) = err.strip().splitlines()
    assert line.startswith("warning: tiny: the scene leaves out vaporization, which would act")
    assert "passes boiling (373.15 K)" in line and "add it to effects" in line


def test_simulate_warns_once_when_the_cut_leaves_the_fine_region(tmp_path, capsys):
    """A graded scene whose crater digs past its 1.5 mm deep fine region: one warning line on
    stderr naming what left it, when and how far; the summary stays on stdout."""
    from diathermy.scene import Resolution
    from tests.engine.scenes import tiny_scene

    res = Resolution(fine_m=0.5e-3, max_cell_m=2e-3, margin_m=1e-3, depth_m=1.5e-3)
    scene = tmp_path / "g.json"
    scene.write_text(tiny_scene(resolution=res, steps=25).model_dump_json())
    assert main(["simulate", str(scene), "--out", str(tmp_path / "g.h5"), "--quiet"]) == 0
    out, err = capsys.readouterr()
    assert "25 steps" in out
    (line,) = err.strip().splitlines()
    assert line.startswith("warning: tiny: the vapor from t = ")  # the vapor leaves first
    assert "the cut from t = " in line and "mm beyond" in line and "resolution.depth_m" in line
