"""A tiny run of benchmarks/incremental_network.py: data from FEM runs, both networks trained,
every predictor scored alone and with the patch on both held-out runs, and the report written."""

from __future__ import annotations

import importlib
import json
import math
import sys
from pathlib import Path

from diathermy.scene.builtin import builtin_scene

ROOT = Path(__file__).resolve().parents[2]
DEFAULT = "x".join(map(str, builtin_scene("default").node_shape))  # the default scene's grid


def _load_benchmark():  # noqa: ANN202 (a module)
    """The benchmark imported by its own name from benchmarks/ (on sys.path, which spawned
    processes inherit): its process pools pickle their tasks by that module's name."""
    path = str(ROOT / "benchmarks")
    if path not in sys.path:
        sys.path.insert(0, path)
    return importlib.import_module("incremental_network")


def test_incremental_network_benchmark_runs_tiny(tmp_path: Path) -> None:
    """The data in processes of their own (--data-only), read back by the run that trains both
    architectures and scores the held-out runs in processes of their own."""
    bench = _load_benchmark()
    out = tmp_path / "inc.md"
    argv = ["--train-runs", "3", "--steps", "5", "--epochs", "1", "--width", "2", "--jobs", "2"]
    argv += ["--work", str(tmp_path / "w")]
    assert bench.main([*argv, "--data-only", "--out", str(out)]) == 0
    assert (tmp_path / "w" / "data.npz").exists() and not out.exists()
    assert bench.main([*argv, "--archs", "pooled", "unet", "--out", str(out)]) == 0
    data = json.loads(out.with_suffix(".json").read_text())
    scenes = {v.name for v in bench.HELD_OUT}
    names = bench.predictors(["pooled", "unet"])
    assert names[:4] == list(bench.PREDICTORS) and "chained-unet" in names
    assert {r["scene"] for r in data["rows"]} == scenes
    for r in data["rows"]:
        for name in names:
            for key in (name, f"{name}+patch"):
                assert math.isfinite(r[f"{key}_error"]) and r[f"{key}_s"] >= 0.0, (r, key)
        # the first mechanics step: persistence has nothing (u_prev = 0), so it misses wholly
        if r is data["rows"][0]:
            assert r["previous_error"] == 1.0
    assert len(data["summary"]) == 2 * len(scenes) * len(names)
    assert set(data["meta"]["history"]) == {"direct", "incremental", "direct-unet",
                                            "incremental-unet"}  # fmt: skip
    text = out.read_text()
    assert "| default | incremental-unet+patch |" in text and "Training history" in text
    # in the engine: persistence, then 'auto' asking each direct network on the first step
    engine = data["meta"]["engine"]
    assert [r["model"] for r in engine] == [None, f"cnn_{DEFAULT}.pt", f"cnn_{DEFAULT}-unet.pt"]
    assert engine[0]["steps"][0]["predictor"] == "none"
    for run in engine[1:]:
        first = run["steps"][0]
        assert first["predictor"] == "cnn" and first["mode"] == "full" and first["iterations"] > 0
    assert f"| cnn_{DEFAULT}-unet.pt |" in text
    for name in ("incremental.pt", "direct-unet.pt"):
        assert (tmp_path / "w" / name).exists()
    # --reuse: the networks read back with their histories, nothing trained again; another
    # width is not the same network and would be trained anew
    reused = tmp_path / "reused.md"
    assert bench.main([*argv, "--archs", "unet", "--reuse", "--out", str(reused)]) == 0
    again = json.loads(reused.with_suffix(".json").read_text())
    assert again["meta"]["history"]["direct-unet"] == data["meta"]["history"]["direct-unet"]
    assert again["meta"]["train_minutes"] == {
        k: v for k, v in data["meta"]["train_minutes"].items() if k.endswith("-unet")
    }
    other = bench.trained_before(tmp_path / "w" / "direct-unet.pt", "direct", "unet",
                                 bench.argparse.Namespace(**{**vars_of(argv), "width": 3}))  # fmt: skip
    assert other is None
    # the direct networks as models for the engine's graded grid, errors against persistence in
    from diathermy.surrogates.checkpoint import grid_mismatch, load_checkpoint

    grid = bench.base_scene().node_grid()
    for sfx in ("", "-unet"):
        path = tmp_path / "w" / f"cnn_{DEFAULT}{sfx}.pt"
        ckpt = load_checkpoint(path, expected_grid=grid.shape)
        assert grid_mismatch(ckpt, grid, path.name) is None
        first = ckpt.metrics["first_mechanics_step"]["default"]
        assert first["previous"] == 1.0 and math.isfinite(first[f"direct{sfx}+patch"])


def vars_of(argv: list[str]) -> dict:
    """The settings ``trained_before`` compares, as the tiny run's arguments give them."""
    opts = dict(zip(argv[::2], argv[1::2], strict=True))
    return {"train_runs": int(opts["--train-runs"]), "steps": int(opts["--steps"]), "seed": 0,
            "epochs": int(opts["--epochs"]), "batch": 2, "lr": 1e-3,
            "width": int(opts["--width"]), "device": "cpu"}  # fmt: skip


def test_bad_arguments_are_one_line_errors(capsys) -> None:  # noqa: ANN001
    bench = _load_benchmark()
    try:
        bench.main(["--train-runs", "1"])
    except SystemExit as exc:
        assert exc.code == 2
    assert "need --train-runs >= 3" in capsys.readouterr().err
