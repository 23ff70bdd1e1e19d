"""Training: it learns, it is deterministic, it resumes, it never mixes scenarios."""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from diathermy.errors import CheckpointError
from diathermy.surrogates import load_checkpoint
from diathermy.surrogates.train_config import COSINE_FLOOR, TrainConfig, learning_rate
from diathermy.surrogates.training import train

FAST = TrainConfig(width=6, depth=3, epochs=6, batch_size=4, lr=3e-3, patience=50, seed=7)


def _weights(path: Path) -> dict[str, torch.Tensor]:
    return load_checkpoint(path).model.state_dict()


def test_training_lowers_the_validation_error(tiny_dataset: Path, tmp_path: Path) -> None:
    result = train(tiny_dataset, tmp_path / "m.pt", FAST, progress=False)
    val = [h["val_loss"] for h in result.history]
    assert result.epochs_run == 6
    assert val[-1] < 0.8 * val[0]
    assert result.best_val_loss == min(val)
    ckpt = load_checkpoint(tmp_path / "m.pt", expected_grid=(9, 9, 17))
    assert ckpt.metrics["best_epoch"] == result.best_epoch
    assert ckpt.training_config["width"] == 6


def test_validation_scenarios_are_held_out_whole(tiny_dataset: Path, tmp_path: Path) -> None:
    result = train(tiny_dataset, tmp_path / "m.pt", replace(FAST, epochs=1), progress=False)
    assert set(result.train_scenarios).isdisjoint(result.val_scenarios)
    assert sorted(result.train_scenarios + result.val_scenarios) == list(range(6))
    data = load_checkpoint(tmp_path / "m.pt").data
    assert data["val_scenarios"] == list(result.val_scenarios)
    with h5py.File(tiny_dataset) as f:
        scen = f["scenario"][...]
    # every step of a validation scenario is in the validation set, none in training
    from diathermy.surrogates.data import read_dataset_info

    info = read_dataset_info(tiny_dataset)
    assert set(scen[info.sample_indices(result.val_scenarios)]) == set(result.val_scenarios)
    assert set(scen[info.sample_indices(result.train_scenarios)]).isdisjoint(result.val_scenarios)


def test_same_seed_gives_the_same_weights(tiny_dataset: Path, tmp_path: Path) -> None:
    cfg = replace(FAST, epochs=2)
    train(tiny_dataset, tmp_path / "a.pt", cfg, progress=False)
    train(tiny_dataset, tmp_path / "b.pt", cfg, progress=False)
    train(tiny_dataset, tmp_path / "c.pt", replace(cfg, seed=8), progress=False)
    a, b, c = (_weights(tmp_path / n) for n in ("a.pt", "b.pt", "c.pt"))
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert not all(torch.equal(a[k], c[k]) for k in a)


def test_resume_continues_where_it_stopped(tiny_dataset: Path, tmp_path: Path) -> None:
    full = train(tiny_dataset, tmp_path / "full.pt", replace(FAST, epochs=4), progress=False)
    train(tiny_dataset, tmp_path / "part.pt", replace(FAST, epochs=2), progress=False)
    resumed = train(
        tiny_dataset, tmp_path / "part.pt", replace(FAST, epochs=4),
        resume=tmp_path / "part.pt", progress=False,
    )  # fmt: skip
    assert resumed.epochs_run == 4 and len(resumed.history) == 4
    assert [h["val_loss"] for h in resumed.history] == [h["val_loss"] for h in full.history]
    a, b = _weights(tmp_path / "full.pt"), _weights(tmp_path / "part.pt")
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_cosine_schedule_runs_from_lr_to_its_floor() -> None:
    assert learning_rate(1e-3, "constant", 0.7) == 1e-3
    assert learning_rate(1e-3, "cosine", 0.0) == pytest.approx(1e-3)
    assert learning_rate(1e-3, "cosine", 0.5) == pytest.approx(1e-3 * (1 + COSINE_FLOOR) / 2)
    assert learning_rate(1e-3, "cosine", 1.0) == pytest.approx(1e-3 * COSINE_FLOOR)
    steps = [learning_rate(1e-3, "cosine", t) for t in np.linspace(0, 1, 50)]
    assert all(a > b for a, b in zip(steps, steps[1:], strict=False))
    with pytest.raises(CheckpointError, match="lr_schedule"):
        TrainConfig(lr_schedule="step")


def test_cosine_resume_follows_the_same_curve(tiny_dataset: Path, tmp_path: Path) -> None:
    """A run stopped after epoch 1 of 3 and resumed ends at the uninterrupted run's weights."""
    cfg = replace(FAST, epochs=3, lr_schedule="cosine")
    full = train(tiny_dataset, tmp_path / "full.pt", cfg, progress=False)

    def stop(entry: dict[str, float]) -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train(tiny_dataset, tmp_path / "part.pt", cfg, progress=False, on_epoch=stop)
    resumed = train(tiny_dataset, tmp_path / "part.pt", cfg, resume=tmp_path / "part.pt",
                    progress=False)  # fmt: skip
    assert [h["val_loss"] for h in resumed.history] == [h["val_loss"] for h in full.history]
    a, b = _weights(tmp_path / "full.pt"), _weights(tmp_path / "part.pt")
    assert all(torch.equal(a[k], b[k]) for k in a)
    state = load_checkpoint(tmp_path / "full.pt").training_state
    assert state is not None
    lr_last = state["optimizer_state"]["param_groups"][0]["lr"]
    assert COSINE_FLOOR * FAST.lr <= lr_last < 0.1 * FAST.lr  # decayed to near its floor


def test_init_from_starts_at_another_models_weights(tiny_dataset: Path, tmp_path: Path) -> None:
    base = train(tiny_dataset, tmp_path / "base.pt", replace(FAST, epochs=2), progress=False)
    zero = train(tiny_dataset, tmp_path / "zero.pt", replace(FAST, epochs=0, seed=3),
                 init_from=base.checkpoint, progress=False)  # fmt: skip
    a, b = _weights(base.checkpoint), _weights(zero.checkpoint)
    assert all(torch.equal(a[k], b[k]) for k in a)  # weights and normaliser buffers alike
    tuned = train(tiny_dataset, tmp_path / "tuned.pt", replace(FAST, epochs=2),
                  init_from=base.checkpoint, progress=False)  # fmt: skip
    assert tuned.val_scenarios == base.val_scenarios  # same seed, same split
    assert tuned.best_val_loss < base.best_val_loss  # it went on from where base ended
    lineage = load_checkpoint(tuned.checkpoint).data["init_from"]  # where it started is recorded
    assert lineage["path"] == str(base.checkpoint) and lineage["init_from"] is None
    assert lineage["metrics"]["best_val_loss"] == base.best_val_loss
    again = train(tiny_dataset, tmp_path / "again.pt", replace(FAST, epochs=1),
                  init_from=tuned.checkpoint, progress=False)  # fmt: skip
    chain = load_checkpoint(again.checkpoint).data["init_from"]
    assert chain["path"] == str(tuned.checkpoint) and chain["init_from"] == lineage
    assert "init_from" not in load_checkpoint(base.checkpoint).data
    train(tiny_dataset, again.checkpoint, replace(FAST, epochs=2), resume=again.checkpoint,
          progress=False)  # fmt: skip
    assert load_checkpoint(again.checkpoint).data["init_from"] == chain  # a resume keeps it
    with pytest.raises(CheckpointError, match="width/depth"):
        train(tiny_dataset, tmp_path / "w.pt", replace(FAST, width=5), init_from=base.checkpoint)
    with pytest.raises(CheckpointError, match="depth must match"):
        train(tiny_dataset, tmp_path / "d.pt", replace(FAST, depth=4), init_from=base.checkpoint)
    wide = train(tiny_dataset, tmp_path / "wide.pt", replace(FAST, width=9, epochs=1),
                 init_from=base.checkpoint, progress=False)  # fmt: skip
    assert load_checkpoint(wide.checkpoint).model.config.width == 9
    assert wide.history[0]["val_loss"] < 1.05 * base.best_val_loss  # it starts where base ended
    with pytest.raises(CheckpointError, match="per_sample_amplitude"):
        train(tiny_dataset, tmp_path / "a.pt", replace(FAST, per_sample_amplitude=False),
              init_from=base.checkpoint)  # fmt: skip
    with pytest.raises(CheckpointError, match="exclude each other"):
        train(tiny_dataset, tmp_path / "x.pt", FAST, resume=base.checkpoint,
              init_from=base.checkpoint)  # fmt: skip


def test_mask_input_fine_tune_starts_at_the_parent_and_learns(
    tiny_dataset: Path, tmp_path: Path
) -> None:
    base = train(tiny_dataset, tmp_path / "base.pt", replace(FAST, epochs=2), progress=False)
    masked = replace(FAST, mask_input=True)
    zero = train(tiny_dataset, tmp_path / "zero.pt", replace(masked, epochs=0),
                 init_from=base.checkpoint, progress=False)  # fmt: skip
    parent, start = load_checkpoint(base.checkpoint).model, load_checkpoint(zero.checkpoint).model
    assert start.config.mask_input and not parent.config.mask_input
    p = 101325.0 + 1e4 * torch.rand(2, 9, 9, 17)
    phi = 1e-2 * torch.randn(2, 9, 9, 17)
    with torch.no_grad():
        torch.testing.assert_close(
            start.predict_displacement(p, phi), parent.predict_displacement(p, phi),
            rtol=0, atol=0,
        )  # fmt: skip
    tuned = train(tiny_dataset, tmp_path / "tuned.pt", replace(masked, epochs=2),
                  init_from=base.checkpoint, progress=False)  # fmt: skip
    assert tuned.best_val_loss < base.best_val_loss
    assert torch.any(load_checkpoint(tuned.checkpoint).model.stem.conv.weight[:, 2] != 0)
    with pytest.raises(CheckpointError, match="--mask-input"):
        train(tiny_dataset, tmp_path / "x.pt", FAST, init_from=tuned.checkpoint)
    fresh = train(tiny_dataset, tmp_path / "fresh.pt", replace(masked, epochs=2), progress=False)
    assert load_checkpoint(fresh.checkpoint).model.config.mask_input
    assert fresh.history[-1]["val_loss"] < fresh.history[0]["val_loss"]


def test_early_stopping(tiny_dataset: Path, tmp_path: Path) -> None:
    # a learning rate this large diverges, so validation stops improving at once
    result = train(
        tiny_dataset, tmp_path / "m.pt", replace(FAST, lr=5.0, epochs=20, patience=2),
        progress=False,
    )  # fmt: skip
    assert result.stopped_early and result.epochs_run < 20
    assert result.epochs_run - result.best_epoch == 2


def test_bf16_autocast_trains_on_cpu(tiny_dataset: Path, tmp_path: Path) -> None:
    result = train(
        tiny_dataset, tmp_path / "m.pt", replace(FAST, epochs=1, amp="bf16"), progress=False
    )
    assert np.isfinite(result.best_val_loss)


def test_bad_options_are_refused(tiny_dataset: Path, tmp_path: Path) -> None:
    with pytest.raises(CheckpointError, match="amp"):
        TrainConfig(amp="fp8")
    with pytest.raises(CheckpointError, match="fp16"):
        train(tiny_dataset, tmp_path / "m.pt", replace(FAST, amp="fp16", device="cpu"))
    other = tmp_path / "other.h5"
    from tests.surrogates.synthetic import write_synthetic_dataset

    write_synthetic_dataset(other, grid=(5, 5, 9), n_scenarios=2, n_steps=1)
    train(tiny_dataset, tmp_path / "m.pt", replace(FAST, epochs=1), progress=False)
    with pytest.raises(CheckpointError, match="trained for grid 9x9x17"):
        train(other, tmp_path / "n.pt", FAST, resume=tmp_path / "m.pt", progress=False)


def test_torchrun_data_parallel_with_gloo(tiny_dataset: Path, tmp_path: Path) -> None:
    """Two CPU processes under torchrun (DistributedSampler + DDP over gloo)."""
    out = tmp_path / "ddp.pt"
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": os.pathsep.join(sys.path)}
    cmd = [
        sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
        "-m", "diathermy", "train", str(tiny_dataset), "--out", str(out), "--epochs", "2",
        "--width", "4", "--depth", "2", "--batch-size", "2", "--device", "cpu", "--quiet",
    ]  # fmt: skip
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "trained 2 epochs" in proc.stdout
    ckpt = load_checkpoint(out)
    assert ckpt.training_state is not None and ckpt.training_state["epoch"] == 2


def test_training_loss_weighs_the_strain() -> None:
    """Weight 0 is the plain L2 loss; the strain term sees a rough error the L2 loss barely sees."""
    from diathermy.surrogates.losses import l2_loss, training_loss

    z = torch.linspace(0, 1, 16)
    target = (z.view(1, 1, -1, 1, 1) * torch.ones(1, 3, 16, 16, 16)).contiguous()
    smooth = target + 0.05  # an offset: no gradient error
    rough = target + 0.05 * torch.where(torch.arange(16) % 2 == 0, 1.0, -1.0).view(1, 1, -1, 1, 1)
    assert training_loss(rough, target, 0.0) == l2_loss(rough, target)
    assert l2_loss(smooth, target) == pytest.approx(float(l2_loss(rough, target)))
    assert training_loss(smooth, target, 1.0) == pytest.approx(float(l2_loss(smooth, target)))
    assert training_loss(rough, target, 1.0) > 100 * training_loss(smooth, target, 1.0)
    assert training_loss(target, target, 1.0) == 0
