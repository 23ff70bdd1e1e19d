"""A tiny run of ``benchmarks/realtime.py solvers`` (benchmarks/realtime_solvers.py): each
variant turns the savings after it off, every variant steps the same checkpoint, the table is
written with each ratio to ``main``."""

from __future__ import annotations

import argparse
from pathlib import Path
from types import ModuleType

import pytest

from tests.benchmarks.loading import load_benchmark
from tests.engine.scenes import tiny_scene


@pytest.fixture(scope="module")
def solvers() -> ModuleType:
    return load_benchmark("realtime_solvers")


def test_variants_step_the_checkpoint_and_the_table_is_written(
    solvers: ModuleType, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    bench = load_benchmark("realtime")
    path, first_cut = bench.warm_up(tiny_scene(), tmp_path / "tiny.h5", 40)
    assert first_cut is not None
    sim = bench.load_as(path, incremental=False)
    solvers.configure(sim, "main")
    mech = sim.ctx.mechanics
    assert mech.krylov.stale_factor == 0.0 and not mech.krylov.ritz  # a new hierarchy each change
    sim = bench.load_as(path, incremental=False)
    solvers.configure(sim, "+reuse")
    assert sim.ctx.mechanics.krylov.stale_factor > 0 and sim.ctx.mechanics.krylov.ritz
    results = {0.0: {v: solvers.run_variant(path, v, 2) for v in solvers.VARIANTS}}
    for rows in results[0.0].values():
        assert len(rows) == 2 and all(r["step_s"] > 0 and r["mech_its"] > 0 for r in rows)
    # "main" sets up a hierarchy on every operator change; the kept ones never more often
    main = sum(r["mech_setups"] for r in results[0.0]["main"])
    assert sum(r["mech_setups"] for r in results[0.0]["+reuse"]) <= main
    monkeypatch.setattr(solvers, "RESULTS", tmp_path)
    solvers.write(results, argparse.Namespace(steps=2, rounds=1), "now")
    table = (tmp_path / "realtime_solvers.md").read_text()
    assert "## uniform 33x33x65" in table
    for v in solvers.VARIANTS:
        assert f"| {v} |" in table
    assert "| main | " in table and " | 1.00 | " in table  # main against itself
