"""Interrupted runs resume to the same file; torn, corrupt and foreign files get clear errors."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from diathermy.datagen import DatagenConfig, DatasetReader, DatasetWriter, generate
from diathermy.datagen.generate import shard_dir_for
from diathermy.datagen.runners import compute_shard
from diathermy.datagen.scenario import run_scenario
from diathermy.datagen.storage import _append_rows
from diathermy.errors import CheckpointError
from tests.datagen.fakes import analytic_physics
from tests.datagen.helpers import assert_same_contents

REPO = Path(__file__).resolve().parents[2]


class Interrupt(Exception):
    pass


def stop_after(k: int):
    def on_commit(index: int) -> None:
        if index + 1 == k:
            raise Interrupt

    return on_commit


@pytest.fixture()
def reference(tmp_path: Path, tiny_config: DatagenConfig) -> Path:
    path = tmp_path / "reference.h5"
    generate(tiny_config, path, factory=analytic_physics)
    return path


@pytest.mark.parametrize("workers", [1, 2])
def test_a_run_stopped_after_k_scenarios_resumes_to_the_same_file(
    tmp_path: Path, tiny_config: DatagenConfig, reference: Path, workers: int
) -> None:
    out = tmp_path / "stopped.h5"
    with pytest.raises(Interrupt):
        generate(
            tiny_config, out, factory=analytic_physics, workers=workers, on_commit=stop_after(2)
        )
    with DatasetReader(out) as r:
        assert len(r) == 12 and r.scenario_ids().tolist() == [0, 1]
    with pytest.raises(CheckpointError, match="--resume"):
        generate(tiny_config, out, factory=analytic_physics)
    summary = generate(tiny_config, out, factory=analytic_physics, workers=workers, resume=True)
    assert summary.complete_scenarios == 4
    assert summary.computed_scenarios + summary.reused_shards == 2
    assert_same_contents(out, reference)


def test_a_torn_tail_is_invisible_and_truncated_on_resume(
    tmp_path: Path, tiny_config: DatagenConfig, reference: Path
) -> None:
    out = tmp_path / "torn.h5"
    with pytest.raises(Interrupt):
        generate(tiny_config, out, factory=analytic_physics, on_commit=stop_after(1))
    physics = analytic_physics(tiny_config)
    with h5py.File(out, "r+") as f:  # half of scenario 1 written, marker not raised: a kill
        samples = list(run_scenario(tiny_config, 1, physics))[:3]
        assert _append_rows(f, samples, tiny_config) == 3
        assert f["pressure"].shape[0] == 9
    with DatasetReader(out) as r:
        assert len(r) == 6 and r.scenario_ids().tolist() == [0]
        with pytest.raises(IndexError):
            r.sample(6)
    generate(tiny_config, out, factory=analytic_physics, resume=True)
    assert_same_contents(out, reference)


def test_finished_shards_are_reused_and_torn_ones_dropped(
    tmp_path: Path, tiny_config: DatagenConfig, reference: Path
) -> None:
    out = tmp_path / "shards.h5"
    with pytest.raises(Interrupt):
        generate(tiny_config, out, factory=analytic_physics, on_commit=stop_after(1))
    shards = shard_dir_for(out)
    compute_shard(tiny_config.model_dump_json(), 2, str(shards), analytic_physics)
    (shards / "scenario_000003.h5.123.tmp").write_bytes(b"half a shard")
    (shards / "scenario_000001.h5").write_bytes(b"not hdf5 at all")
    summary = generate(tiny_config, out, factory=analytic_physics, resume=True)
    assert summary.reused_shards == 1 and summary.computed_scenarios == 2
    assert not shards.exists()
    assert_same_contents(out, reference)


def test_more_scenarios_extend_a_finished_file(
    tmp_path: Path, tiny_config: DatagenConfig, reference: Path
) -> None:
    out = tmp_path / "grow.h5"
    generate(tiny_config.model_copy(update={"n_scenarios": 2}), out, factory=analytic_physics)
    generate(tiny_config, out, factory=analytic_physics, resume=True)
    assert_same_contents(out, reference)


def test_sigkill_mid_scenario_then_resume(
    tmp_path: Path, tiny_config: DatagenConfig, reference: Path
) -> None:
    out = tmp_path / "killed.h5"
    script = (
        "import sys\n"
        "from diathermy.datagen import DatagenConfig, generate\n"
        "from tests.datagen.fakes import analytic_physics\n"
        "config = DatagenConfig.model_validate_json(sys.argv[1])\n"
        "generate(config, sys.argv[2], factory=analytic_physics,\n"
        "         on_commit=lambda i: print('committed', i, flush=True))\n"
    )
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(REPO / "server"), str(REPO)]),
        "DIATHERMY_TEST_DELAY_S": "0.05",  # 0.3 s per scenario: the kill lands mid-scenario
    }
    proc = subprocess.Popen(
        [sys.executable, "-c", script, tiny_config.model_dump_json(), str(out)],
        stdout=subprocess.PIPE,
        text=True,
        env=env,
        cwd=REPO,
    )
    assert proc.stdout is not None
    deadline = time.monotonic() + 60
    for line in proc.stdout:
        if line.strip() == "committed 1" or time.monotonic() > deadline:
            break
    time.sleep(0.1)  # inside scenario 2's solves
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL
    with DatasetReader(out) as r:
        assert r.scenario_ids().tolist() == [0, 1]
    summary = generate(tiny_config, out, factory=analytic_physics, resume=True)
    assert summary.computed_scenarios == 2
    assert_same_contents(out, reference)


def test_resume_with_another_config_is_refused(
    tmp_path: Path, tiny_config: DatagenConfig, reference: Path
) -> None:
    other = tiny_config.model_copy(update={"p_max_pa": 7e5})
    with pytest.raises(CheckpointError, match="field p_max_pa"):
        generate(other, reference, factory=analytic_physics, resume=True)
    fewer = tiny_config.model_copy(update={"n_scenarios": 2})
    with pytest.raises(CheckpointError, match="already holds 4 scenarios"):
        DatasetWriter(reference, fewer, resume=True)


def test_non_hdf5_foreign_and_corrupt_files_get_clear_errors(
    tmp_path: Path, tiny_config: DatagenConfig, reference: Path
) -> None:
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"this is not HDF5" * 100)
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["x"] = np.arange(3)
        f.attrs["format"] = "diathermy-run"
    cut = tmp_path / "cut.h5"
    cut.write_bytes(reference.read_bytes()[: reference.stat().st_size // 3])
    missing = tmp_path / "missing.h5"
    with h5py.File(reference, "r") as src, h5py.File(missing, "w") as dst:
        dst.attrs.update(src.attrs)
        src.copy("pressure", dst)
    for path, message in (
        (junk, "not a readable HDF5 file"),
        (foreign, "not a diathermy-dataset file"),
        (cut, "not a readable HDF5 file"),
        (missing, "lacks dataset"),
    ):
        with pytest.raises(CheckpointError, match=message):
            DatasetReader(path)
        with pytest.raises(CheckpointError, match=message):
            generate(tiny_config, path, factory=analytic_physics, resume=True)
