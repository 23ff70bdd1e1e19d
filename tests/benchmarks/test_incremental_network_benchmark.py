"""A tiny run of benchmarks/incremental_network.py: data from FEM runs, both networks trained,
every predictor scored alone and with the patch on both held-out runs, and the report written."""

from __future__ import annotations

import importlib.util
import json
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _load_benchmark():  # noqa: ANN202 (a module)
    spec = importlib.util.spec_from_file_location(
        "incremental_bench", ROOT / "benchmarks/incremental_network.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def test_incremental_network_benchmark_runs_tiny(tmp_path: Path) -> None:
    bench = _load_benchmark()
    out = tmp_path / "inc.md"
    argv = ["--train-runs", "3", "--steps", "5", "--epochs", "1", "--width", "2"]
    assert bench.main([*argv, "--work", str(tmp_path / "w"), "--out", str(out)]) == 0
    data = json.loads(out.with_suffix(".json").read_text())
    scenes = {v.name for v in bench.HELD_OUT}
    assert {r["scene"] for r in data["rows"]} == scenes
    for r in data["rows"]:
        for name in bench.PREDICTORS:
            for key in (name, f"{name}+patch"):
                assert math.isfinite(r[f"{key}_error"]) and r[f"{key}_s"] >= 0.0, (r, key)
        # the first mechanics step: persistence has nothing (u_prev = 0), so it misses wholly
        if r is data["rows"][0]:
            assert r["previous_error"] == 1.0
    assert len(data["summary"]) == 2 * len(scenes) * len(bench.PREDICTORS)
    text = out.read_text()
    assert "| default | incremental+patch |" in text and "Training history" in text
    assert (tmp_path / "w" / "incremental.pt").exists()


def test_bad_arguments_are_one_line_errors(capsys) -> None:  # noqa: ANN001
    bench = _load_benchmark()
    try:
        bench.main(["--train-runs", "1"])
    except SystemExit as exc:
        assert exc.code == 2
    assert "need --train-runs >= 3" in capsys.readouterr().err
