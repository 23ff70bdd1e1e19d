"""A tiny run of benchmarks/resolution_prototype.py: it runs end to end and writes its table."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_resolution_prototype_runs_tiny_grids(tmp_path: Path) -> None:
    spec = importlib.util.spec_from_file_location(
        "resolution_prototype", ROOT / "benchmarks/resolution_prototype.py"
    )
    assert spec is not None and spec.loader is not None
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    out = bench.main(
        ["--uniform-nz", "9", "--fine-mm", "6", "--margin-mm", "8", "--out", str(tmp_path / "r.md")]
    )
    text = out.read_text()
    assert "| uniform 9x9x17 |" in text and "| graded 6 mm" in text
    assert "reference 42.52 W" in text
