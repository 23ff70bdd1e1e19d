"""A tiny run of benchmarks/resolution_prototype.py: it runs end to end and writes its table."""

from __future__ import annotations

from pathlib import Path

from tests.benchmarks.loading import load_benchmark


def test_resolution_prototype_runs_tiny_grids(tmp_path: Path) -> None:
    bench = load_benchmark("resolution_prototype")
    out = bench.main(
        ["--uniform-nz", "9", "--fine-mm", "6", "--margin-mm", "8", "--out", str(tmp_path / "r.md")]
    )
    text = out.read_text()
    assert "| uniform 9x9x17 |" in text and "| graded 6 mm" in text
    assert "reference 42.52 W" in text
