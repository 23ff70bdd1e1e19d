"""A tiny run of benchmarks/guard_estimate.py: every incremental mechanics answer checked against
the same system solved tight, and the table."""

from __future__ import annotations

import argparse
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from tests.benchmarks.loading import load_benchmark
from tests.engine.scenes import tiny_scene


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    return load_benchmark("guard_estimate")


def test_estimates_are_checked_against_a_tight_solve(bench: ModuleType, tmp_path: Path) -> None:
    data = tiny_scene().model_dump()
    data["mechanics"]["guard"] = "energy"  # the tiny grid is uniform: 'auto' is the residual
    scene = type(tiny_scene()).model_validate(data)
    path, first_cut = bench.warm_up(scene, tmp_path / "tiny.h5", 40)
    assert first_cut is not None
    rows = bench.record(bench.load_as(path), 6)
    assert len(rows) == 6 and {r["mode"] for r in rows} <= {"local", "full"}
    for r in rows:
        assert np.isfinite(r["true"]) and 0 <= r["true"] < 0.1
        if r["mode"] == "local":  # accepted on its estimate
            assert r["estimate"] <= r["tolerance"]
    # the engine's answers are not exact: a local step's true error is not zero
    assert any(r["true"] > 1e-9 for r in rows if r["mode"] == "local")
    args = argparse.Namespace(scenes=["tiny"], grids=["own"], steps=6)
    text = bench.write({"tiny, own": rows}, args, "now")
    assert "| tiny, own | 6 |" in text or "| tiny, own |" in text
    assert text.count("| tiny, own |") >= len(rows)


def test_a_backend_that_is_not_incremental_is_refused(bench: ModuleType, tmp_path: Path) -> None:
    path, _ = bench.warm_up(tiny_scene(), tmp_path / "tiny.h5", 40)
    sim = bench.load_as(path, incremental=False)
    with pytest.raises(SystemExit, match="not the incremental"):
        bench.record(sim, 1)
