"""A tiny run of benchmarks/service.py end to end, and its server start-up failing clearly."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from tests.benchmarks.loading import load_benchmark

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "service.py"


def _load_benchmark() -> ModuleType:
    return load_benchmark("service")


def test_service_benchmark_runs_tiny_and_writes_its_table(tmp_path: Path) -> None:
    out = tmp_path / "service.md"
    args = ["--grids", "5x5x9", "--slow-grid", "5x5x9", "--clients", "1,2", "--reps", "1"]
    args += ["--dtype", "float16", "--region", "top"]  # the clients' subscription, in the header
    run = subprocess.run(
        [sys.executable, str(SCRIPT), *args, "--seconds", "0.5", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    text = out.read_text()
    assert "CPU server / engine / clients" in text and "(float16 top)" in text
    rows = [ln for ln in text.splitlines() if ln.startswith(("| 1 |", "| 2 |"))]
    assert len(rows) == 2, text
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split("|")]
        steps_per_s, fps = float(cells[1]), float(cells[3])
        engine_cpu = float(cells[12].split("/")[1])
        assert steps_per_s > 0 and fps > 0 and engine_cpu > 0, row
        assert 0 <= float(cells[14].rstrip(" %")) <= 100, row  # the host's steal time


def test_a_server_that_cannot_start_is_a_clear_error(tmp_path: Path) -> None:
    bench = _load_benchmark()
    not_a_directory = tmp_path / "file"
    not_a_directory.write_text("")
    with pytest.raises(RuntimeError, match="exited with code"):
        bench.Server(not_a_directory)


def test_latency_counts_the_first_frame_showing_the_control_even_before_its_ack() -> None:
    bench = _load_benchmark()
    sent = {1: 10.0, 2: 20.0, 3: 30.0}
    acked = {1: 5, 2: 6}  # control 3 was never acked: not counted
    frames = [(9.0, 5, 99), (10.5, 4, 100), (10.8, 5, 101), (20.2, 6, 102), (31.0, 7, 103)]
    got = bench.control_latencies(sent, acked, frames)
    # the frame before the send does not count, even though its control_id is high enough
    assert got == [(pytest.approx(0.8), 101), (pytest.approx(0.2), 102)]


def test_the_client_reads_a_frames_header_and_skips_its_arrays() -> None:
    from benchmarks.service_client import HEAD_BYTES, read_head
    from diathermy.service.encoding import encode_array, pack
    from diathermy.service.hub import Frame

    big = encode_array(np.zeros((40, 40, 80), dtype=np.float32))
    msg = {"type": "frame", "step": 9, "control_id": 4, "report": {"wall_s": 0.04}}
    data = Frame.encode({**msg, "fields": {"temperature": big}}).to_bytes(2)
    assert len(data) > HEAD_BYTES
    assert read_head(data[:HEAD_BYTES], len(data)) == {"dropped": 2, **msg}
    small = pack({"type": "ack", "control_id": 3})
    assert read_head(small, len(small)) == {"type": "ack", "control_id": 3}


def test_the_latency_trace_runs_tiny(tmp_path: Path) -> None:
    out = tmp_path / "trace.md"
    args = ["--grids", "5x5x9", "--clients", "1", "--seconds", "0.6", "--variants", "now"]
    run = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "service_trace.py"), *args, "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    text = out.read_text()
    step_row = next(ln for ln in text.splitlines() if ln.startswith("| its step (engine)"))
    p50 = float(step_row.split("|")[2].split("/")[0])  # the engine's hooks reported
    assert p50 > 0, text
