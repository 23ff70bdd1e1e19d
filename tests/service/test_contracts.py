"""The published contracts: stale-file check, and schemathesis fuzzing against a live server."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from diathermy.service.engine import DefaultEngine
from diathermy.service.openapi import contract_files
from tests.service.conftest import TOKEN_A, LiveServer, make_settings

ROOT = Path(__file__).resolve().parents[2]


def test_contract_files_are_fresh() -> None:
    for name, text in contract_files().items():
        path = ROOT / "openapi" / name
        assert path.read_text(encoding="utf-8") == text, (
            f"openapi/{name} is stale: run `diathermy openapi --out openapi`"
        )


CHECKS = (
    "not_a_server_error",
    "status_code_conformance",
    "content_type_conformance",
    "negative_data_rejection",
    "response_schema_conformance",
)
"""What schemathesis checks on every response: no 5xx, only documented status codes and content
types, invalid input refused, and bodies that match their schema."""


def test_schemathesis_finds_no_contract_violations(tmp_path: Path) -> None:
    settings = make_settings(tmp_path / "data", max_sessions_per_token=200)
    live = LiveServer(settings, DefaultEngine()).start()
    try:
        tail = run_schemathesis(live, tmp_path)
    finally:
        live.stop()
    assert "passed" in tail.lower()
    steps = live.state.metrics.registry.get_sample_value("diathermy_step_seconds_count")
    assert steps, "the fuzzer never stepped a session it created: check the OpenAPI links"


def run_schemathesis(live: LiveServer, tmp_path: Path) -> str:
    exe = shutil.which("schemathesis") or shutil.which("st")
    cmd = [exe] if exe else [sys.executable, "-m", "schemathesis.cli"]
    proc = subprocess.run(
        [
            *cmd,
            "run",
            str(ROOT / "openapi" / "openapi.json"),
            "--url",
            live.url,
            "--checks",
            ",".join(CHECKS),
            "--max-examples",
            "15",
            # the coverage phase (every boundary of every schema, ~2000 requests, about a
            # minute here) is left to a manual run; fuzzing draws negative data too
            "--phases",
            "examples,fuzzing,stateful",
            "--mode",
            "all",
            "--seed",
            "1",
            "--header",
            f"Authorization: Bearer {TOKEN_A}",
            "--report-dir",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        timeout=90,
        cwd=tmp_path,
    )
    tail = (proc.stdout + proc.stderr)[-4000:]
    assert proc.returncode == 0, tail
    return tail
