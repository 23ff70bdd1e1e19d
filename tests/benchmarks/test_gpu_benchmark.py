"""A tiny run of benchmarks/gpu.py on the CPU: inference rows for every network and device this
machine has, whole steps per mode with their errors against the full solve, the report."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from diathermy.scene.builtin import builtin_scene

ROOT = Path(__file__).resolve().parents[2]
DEFAULT = "x".join(map(str, builtin_scene("default").node_shape))  # the default scene's grid


def test_gpu_benchmark_runs_tiny_on_the_cpu(tmp_path: Path) -> None:
    out = tmp_path / "gpu.md"
    cmd = [sys.executable, str(ROOT / "benchmarks/gpu.py"), "--grids", "default", "9x9x17",
           "--step-grids", "default", "--repeat", "2", "--steps", "2", "--warmup-steps", "8",
           "--out", str(out)]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=240)
    assert done.returncode == 0, done.stderr[-2000:]
    data = json.loads(out.with_suffix(".json").read_text())
    models = {r["model"] for r in data["inference"]}
    assert models == {"direct (paper)", "incremental"}
    assert {r["grid"] for r in data["inference"]} == {
        f"{DEFAULT} graded (default)",
        "9x9x17 uniform",
    }
    for r in data["inference"]:
        assert 0 < r["forward_median_s"] <= r["forward_p90_s"]
        assert 0 < r["call_median_s"] <= r["call_p90_s"]
    (step,) = data["steps"]
    assert step["mechanics_ran"] and step["first_cut_step"] is not None
    modes = step["devices"]["cpu"]["modes"]
    assert set(modes) == {"full", "incremental"}  # no CNN on the graded grid
    assert modes["full"]["max_se_error"] == 0.0
    assert 0.0 <= modes["incremental"]["max_se_error"] < 0.01
    text = out.read_text()
    assert f"| {DEFAULT} graded (default) | default | - | cpu | incremental | 2 |" in text
    assert "no GPU (CUDA not available" in text


def test_bad_grid_is_a_one_line_error() -> None:
    cmd = [sys.executable, str(ROOT / "benchmarks/gpu.py"), "--grids", "2x9"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert "grid '2x9'" in done.stderr and "Traceback" not in done.stderr
