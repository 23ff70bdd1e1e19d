"""A tiny run of benchmarks/hybrid.py: the harness runs end to end and writes its report."""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

import torch

from diathermy.datagen.engine_samples import EngineSamplesConfig, random_scene
from diathermy.mesh import Grid
from diathermy.surrogates import CNNConfig, DisplacementCNN, FieldScales, save_checkpoint
from tests.benchmarks.loading import load_benchmark

TINY = EngineSamplesConfig(
    grid=(7, 7, 13), block_m=(0.02, 0.01, 0.01), n_steps=9, power_w=(30.0, 40.0),
    margin_m=0.004, seed=3,
)  # fmt: skip


def _load_benchmark() -> ModuleType:
    return load_benchmark("hybrid")


def test_hybrid_benchmark_runs_a_tiny_scene_and_writes_its_report(tmp_path: Path) -> None:
    bench = _load_benchmark()
    torch.manual_seed(0)
    model = DisplacementCNN(
        CNNConfig(width=2, depth=1), FieldScales(pressure_scale_pa=1e5, per_sample_amplitude=True)
    )
    path = tmp_path / "tiny.pt"
    spacing = Grid(TINY.grid, size_m=TINY.block_m).spacing_m
    save_checkpoint(path, model, grid_shape=TINY.grid, spacing_m=spacing)
    scene = random_scene(TINY, 0)
    part = bench.run_scene(scene, TINY.n_steps, str(path), 1e-3)
    assert part["rows"], "the tiny scene must reach the mechanics"
    for row in part["rows"]:
        assert row["guard_error"] <= row["raw_error"] + 1e-12  # the guard only ever helps
        assert row["guard_residual_after"] <= 1e-3
        assert row["patch_patch_nodes"] > 0 and row["cnn_patch_nodes"] == 0
        # persistence beside the network: the patch only ever brings it nearer equilibrium
        assert 0.0 <= row["prevpatch_error"] and row["prevpatch_s"] >= 0.0
        assert row["prevpatch_residual_after"] <= row["prev_residual_after"] + 1e-12
    assert part["rows"][0]["prev_error"] == 1.0  # the first mechanics step: persistence has u = 0
    assert max(r["prev_error"] for r in part["rows"][1:]) < 1.0
    assert set(part["coupled"]) == {"cnn", "patch", "guard", "prev", "prevpatch", "prevguard"}
    bench.write_report([part], tmp_path, wall_s=1.0)
    report = (tmp_path / "hybrid.md").read_text()
    assert scene.name in report and "| CNN+patch+guard |" in report
    assert "| previous+patch |" in report  # the coupled persistence run
    assert "persistence beside the network" in report
    assert (tmp_path / "hybrid.png").stat().st_size > 0
