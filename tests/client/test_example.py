"""examples/moving_electrode.py runs against a live server and saves a picture of the cut."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from tests.client.conftest import ROOT, TOKEN_A, LiveServer


def test_moving_electrode_example(live: LiveServer, tmp_path: Path) -> None:
    out = tmp_path / "cut.png"
    proc = subprocess.run(
        [
            sys.executable,
            str(ROOT / "examples" / "moving_electrode.py"),
            "--grid",
            "5x5x9",
            "--out",
            str(out),
        ],
        env={
            "PYTHONPATH": str(ROOT / "client"),  # the SDK alone: no server packages
            "PATH": "/usr/bin:/bin",
            "DIATHERMY_URL": live.url,
            "DIATHERMY_TOKEN": TOKEN_A,
            "MPLBACKEND": "Agg",
            "HOME": str(tmp_path),
        },
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "cut from step" in proc.stdout
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 5000
    assert live.state.registry.sessions == {}  # the example cleaned up its session
