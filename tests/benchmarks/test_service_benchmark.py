"""A tiny run of benchmarks/service.py end to end, and its server start-up failing clearly."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "service.py"


def _load_benchmark():  # noqa: ANN202 (a module)
    spec = importlib.util.spec_from_file_location("service_benchmark", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_service_benchmark_runs_tiny_and_writes_its_table(tmp_path: Path) -> None:
    out = tmp_path / "service.md"
    args = ["--grids", "5x5x9", "--slow-grid", "5x5x9", "--clients", "1,2", "--reps", "1"]
    run = subprocess.run(
        [sys.executable, str(SCRIPT), *args, "--seconds", "0.5", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    text = out.read_text()
    assert "CPU server / engine / clients" in text
    rows = [ln for ln in text.splitlines() if ln.startswith(("| 1 |", "| 2 |"))]
    assert len(rows) == 2, text
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split("|")]
        steps_per_s, fps = float(cells[1]), float(cells[3])
        engine_cpu = float(cells[10].split("/")[1])
        assert steps_per_s > 0 and fps > 0 and engine_cpu > 0, row


def test_a_server_that_cannot_start_is_a_clear_error(tmp_path: Path) -> None:
    bench = _load_benchmark()
    not_a_directory = tmp_path / "file"
    not_a_directory.write_text("")
    with pytest.raises(RuntimeError, match="exited with code"):
        bench.Server(not_a_directory)
