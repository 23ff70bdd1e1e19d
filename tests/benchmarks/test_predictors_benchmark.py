"""A tiny run of benchmarks/predictors.py: every named case is reached and scored, for
persistence and a network, alone and with the patch, and the report holds them in one table."""

from __future__ import annotations

import math
from pathlib import Path

from diathermy.mesh import build_tet_mesh
from diathermy.surrogates.predictor import CNNPredictor
from tests.benchmarks.loading import load_benchmark
from tests.engine.scenes import tiny_scene
from tests.surrogates.hybrid_helpers import untrained_model

ROOT = Path(__file__).resolve().parents[2]


def _load_benchmark():  # noqa: ANN202 (a module)
    return load_benchmark("predictors")


def test_predictors_benchmark_scores_every_case_on_a_tiny_scene(tmp_path: Path) -> None:
    bench = _load_benchmark()
    scene = tiny_scene()
    model = untrained_model(tmp_path / "n.pt")
    network = CNNPredictor(build_tet_mesh(scene.node_grid()), model)
    rows = bench.run_cases(scene, network, steady_steps=2, place_steps=3, erratic_steps=2)
    assert {r["case"] for r in rows} == set(bench.CASES)
    for r in rows:
        for k in bench.PREDICTORS:
            assert math.isfinite(r[f"{k}_error"]) and r[f"{k}_s"] >= 0.0, (r["case"], k)
        # the patch is a Galerkin correction: never farther from equilibrium than its start
        assert r["previous+patch_residual"] <= r["previous_residual"] + 1e-12
        assert r["cnn+patch_residual"] <= r["cnn_residual"] + 1e-12
    first = next(r for r in rows if r["case"] == "first-step")
    assert first["previous_error"] == 1.0  # persistence has nothing: u = 0
    assert first["auto_pick"] == "cnn"
    cut = next(r for r in rows if r["case"] == "cut-event")
    assert cut["removed_tets"] > 0
    steady = [r for r in rows if r["case"] == "steady"]
    assert all(r["previous+patch_error"] < 0.05 for r in steady)
    assert all(r["auto_pick"] == "previous" for r in steady)
    engine = bench.engine_first_steps(scene, str(model), steps=2)
    first_auto = next(e for e in engine if e["setting"] == "auto")
    assert first_auto["predictor"] == "cnn" and "no previous displacement" in first_auto["why"]
    assert [e["predictor"] for e in engine if e["setting"] == "previous"][0] == "none"
    bench.write_report(
        rows, tmp_path, {"command": "x", "machine": "m", "grid": "9x9x17", "power_w": 30,
                         "model": "n.pt", "load": "0", "wall_s": 1.0}, engine=engine,
    )  # fmt: skip
    report = (tmp_path / "predictors.md").read_text()
    for case in bench.CASES:
        assert f"| {case} |" in report
    assert "previous+patch max / mean" in report and "cnn+patch max / mean" in report
    assert "| auto |" in report  # the engine's own first steps under 'auto'
    lifted = [r for r in rows if r["case"] == "lift-and-place"]
    assert len(lifted) == 3
