"""A tiny run of benchmarks/realtime.py: warm-up to the cut, the modes in lockstep, the errors
against the full mode, and the results table and plot."""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from pathlib import Path
from types import ModuleType

import pytest

from tests.engine.scenes import tiny_scene

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    spec = importlib.util.spec_from_file_location("realtime", ROOT / "benchmarks/realtime.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_tiny_run_writes_its_table(bench: ModuleType, tmp_path: Path) -> None:
    scene = tiny_scene()
    assert bench.modes_for(scene) == ["full", "incremental"]  # no model for a 9x9x17 grid
    assert bench.modes_for(bench.scene_on("coagulation", "uniform")) == ["full", "incremental"]
    assert bench.modes_for(scene, tight=True)[-1] == bench.TIGHT_MODE
    loose = f"{bench.TOLERANCE_MODE}0.01"
    assert bench.modes_for(scene, tolerances=(1e-2,))[-1] == loose
    run = bench.measure(
        scene, tmp_path / "tiny.h5", warmup=40, steps=4, tight=True, tolerances=(1e-2,)
    )
    assert run["first_cut"] is not None and (tmp_path / "tiny.json").exists()
    rec = run["rec"]
    assert rec["full"]["se_err"] == [0.0] * 4 and rec["full"]["local"] == [0.0] * 4
    for mode in ("incremental", bench.TIGHT_MODE, loose):  # the default, the settings before it
        assert max(rec[mode]["se_err"]) <= 0.01 and max(rec[mode]["dT_k"]) <= 0.1
    sim = bench.load_mode(tmp_path / "tiny.h5", loose)
    assert sim.scene.mechanics.energy_tolerance == 1e-2
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
        scenes=["tiny"], grids=["own"], steps=4, tight=True, tolerances=[1e-2]
    )
    bench.write_run({("tiny", "own"): run}, args, "now", out=tmp_path)
    table = (tmp_path / "realtime.md").read_text()
    assert "| tiny | 9x9x17 uniform | 1,377 |" in table and "| incremental |" in table
    assert f"| {bench.TIGHT_MODE} |" in table and "--tight" in table
    assert f"| {loose} |" in table and "--tolerances 0.01" in table
    assert (tmp_path / "realtime.png").stat().st_size > 1000
