"""benchmarks/realtime_timers.py: nested timers that add up, probes put back, and a tiny graded
run's table with the mechanics' parts."""

from __future__ import annotations

import argparse
import re
import time
from pathlib import Path
from types import ModuleType

import pytest

from diathermy.engine.simulation import Simulation
from diathermy.scene import Resolution
from tests.benchmarks.loading import load_benchmark
from tests.engine.scenes import tiny_scene


@pytest.fixture(scope="module")
def timers_mod() -> ModuleType:
    return load_benchmark("realtime_timers")


def test_a_callers_own_time_leaves_out_its_timed_callees(timers_mod: ModuleType) -> None:
    t = timers_mod.Timers()
    inner = t.wrap("inner", lambda: time.sleep(0.02))

    def outer_body() -> None:
        time.sleep(0.01)
        inner()
        inner()

    outer = t.wrap("outer", outer_body)
    t0 = time.perf_counter()
    outer()
    total = time.perf_counter() - t0
    assert t.calls == {"outer": 1, "inner": 2}
    assert t.own["inner"] == pytest.approx(0.04, abs=0.02)
    assert t.own["outer"] == pytest.approx(0.01, abs=0.01)
    assert t.own["outer"] + t.own["inner"] == pytest.approx(total, rel=1e-3, abs=1e-4)


def test_the_probes_are_put_back(timers_mod: ModuleType) -> None:
    import diathermy.fem.galerkin_refresh as gr
    import diathermy.physics.incremental_mechanics as im

    before = (im.choose_start, gr.GalerkinRefresh.__dict__["refresh"])
    with timers_mod.probed(timers_mod.Timers()):
        assert im.choose_start is not before[0]
        assert gr.GalerkinRefresh.__dict__["refresh"] is not before[1]
    assert (im.choose_start, gr.GalerkinRefresh.__dict__["refresh"]) == before
    with pytest.raises(RuntimeError), timers_mod.probed(timers_mod.Timers()):
        raise RuntimeError("a failing step")
    assert im.choose_start is before[0]


def test_a_tiny_graded_run_writes_a_table_that_adds_up(
    timers_mod: ModuleType, tmp_path: Path
) -> None:
    res = Resolution(fine_m=0.5e-3, max_cell_m=2e-3, margin_m=1e-3, depth_m=1.5e-3)
    sim = Simulation(tiny_scene(resolution=res))
    for _ in range(20):  # past the first cut: the incremental path's parts run
        sim.step()
    assert sim.last_report is not None and sim.last_report.cut_volume_m3 > 0
    args = argparse.Namespace(scenes=["tiny"], grids=["own"], steps=3, out=tmp_path)
    out = timers_mod.timers(args, "now", lambda name, grid: sim)
    text = out.read_text()
    assert out == tmp_path / "realtime_timers.md"
    assert "## tiny," in text and "graded" in text
    for part in ("| mechanics |", "| - patch |", "| - start (Ritz scale) |", "| electric |"):
        assert part in text
    ms = {
        label: float(value)
        for label, value in re.findall(r"^\| ([^|]+?) \| (-?[\d.]+) \| -?\d+% \|", text, re.M)
    }
    parts = [v for k, v in ms.items() if k.startswith("- ") and k != "- the rest of the mechanics"]
    # each part's own time leaves its timed callees out: counted twice, the parts would pass the
    # mechanics' wall time and leave a negative rest
    assert parts and sum(parts) <= ms["mechanics"] + 0.1
    assert ms["- the rest of the mechanics"] >= 0.0
    assert ms["outside the effects (the step's bookkeeping and report)"] >= 0.0
