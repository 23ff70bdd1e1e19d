"""A tiny run of benchmarks/viewer.py: server, page and both measurements end to end."""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

from tests.benchmarks.loading import load_benchmark


def _load_benchmark() -> ModuleType:
    return load_benchmark("viewer")


def test_viewer_benchmark_runs_tiny_and_writes_its_table(tmp_path: Path) -> None:
    bench = _load_benchmark()
    text = bench.run(
        tmp_path, seconds=0.5, default_steps=2, grid=[5, 5, 9], picture_too=False, redraws=5
    )
    assert (tmp_path / "viewer.md").read_text() == text
    rows = [ln for ln in text.splitlines() if ln.startswith("| 5x5x9") or ln.startswith("| 9x9x17")]
    assert len(rows) == 2, text
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split("|")]
        redraw_fps = float(cells[8])
        assert redraw_fps > 0, row
    quick = [c.strip() for c in rows[1].strip("|").split("|")]
    assert int(quick[2]) > 0, "the quick-cut session must show cut faces"
