"""A tiny run of benchmarks/fixed_depth.py: a scene with and without a deep tier, two steps
each, and the report's table from the saved runs."""

from __future__ import annotations

import json
from pathlib import Path
from types import ModuleType

import pytest

from tests.benchmarks.loading import load_benchmark


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    return load_benchmark("fixed_depth")


def test_the_tier_deepens_the_fine_region_and_the_report_compares(
    bench: ModuleType, tmp_path: Path
) -> None:
    for deep in (0.0, 30.0):
        bench.run_one(deep, 0.06, tmp_path, "test", base="default")
    plain = json.loads((tmp_path / "fixed_depth_notier.json").read_text())
    tier = json.loads((tmp_path / "fixed_depth_deep30.json").read_text())
    assert plain["region_bottom_mm"] == pytest.approx(16.0)
    assert tier["region_bottom_mm"] == pytest.approx(30.0)
    assert tier["nodes"] > plain["nodes"] and tier["shape"][1:] == plain["shape"][1:]
    assert len(plain["steps"]) == len(tier["steps"]) == 2
    assert all(s["power_w"] == pytest.approx(50.0, rel=1e-6) for s in tier["steps"])
    table = bench.report(tmp_path).read_text()
    assert "| notier " in table and "| deep30 " in table and "`test`" in table
    assert bench.at(tier["steps"], 0.06, "time_s") == pytest.approx(0.06)
    assert bench.at(tier["steps"], 1.5, "time_s") is None  # past the run's end
    assert bench.left_at(tier["steps"]) is None


def test_bad_arguments_are_one_line_errors(bench: ModuleType, tmp_path: Path) -> None:
    with pytest.raises(SystemExit):
        bench.main(["run", "--deep-mm", "-1", "--out", str(tmp_path)])
    with pytest.raises(SystemExit, match="no fixed_depth"):
        bench.main(["report", "--out", str(tmp_path)])
