"""A training job: train the CNN on a dataset job's output, evaluate it, register the model.

A retried job resumes from its last epoch's checkpoint (``train(resume=...)``). With launcher
``torchrun`` the training runs data-parallel under ``torch.distributed.run`` (progress is then
the trainer's output in the job log, and the fraction jumps to 1 at the end).
"""

from __future__ import annotations

import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

from diathermy.errors import CheckpointError
from diathermy.surrogates.checkpoint import load_checkpoint
from diathermy.surrogates.evaluation import evaluate_model
from diathermy.surrogates.train_config import TrainConfig
from diathermy.surrogates.training import train
from diathermy.worker.context import JobContext, eta_s
from diathermy.worker.job_records import JobProgress
from diathermy.worker.layout import job_dir
from diathermy.worker.registry import ModelInfo, activate_model, list_models, register_model
from diathermy.worker.specs import JobState, TrainingJobSpec

CHECKPOINT = "model.pt"


def torchrun_command(
    data: Path, out: Path, config: TrainConfig, *, nproc_per_node: int, resume: Path | None
) -> list[str]:
    """``python -m torch.distributed.run ... -m diathermy train`` for one node."""
    cmd = [
        sys.executable, "-m", "torch.distributed.run", "--standalone",
        f"--nproc_per_node={nproc_per_node}", "-m", "diathermy", "train", str(data),
        "--out", str(out), "--width", str(config.width), "--depth", str(config.depth),
        "--epochs", str(config.epochs), "--batch-size", str(config.batch_size),
        "--lr", repr(config.lr), "--val-fraction", repr(config.val_fraction),
        "--patience", str(config.patience), "--seed", str(config.seed), "--amp", config.amp,
        "--device", config.device, "--workers", str(config.num_workers),
        "--strain-weight", repr(config.strain_weight), "--lr-schedule", config.lr_schedule,
        "--scale-samples", str(config.scale_samples),
        "--energy-weight", repr(config.energy_weight),
        "--arch", config.arch, "--levels", str(config.levels),
        "--quiet",
    ]  # fmt: skip
    if not config.per_sample_amplitude:
        cmd.append("--global-amplitude")
    if config.mask_input:
        cmd.append("--mask-input")
    return cmd + (["--resume", str(resume)] if resume is not None else [])


def _resumable(ctx: JobContext, ckpt: Path, grid: tuple[int, int, int]) -> Path | None:
    if not ckpt.exists():
        return None
    try:
        loaded = load_checkpoint(ckpt, expected_grid=grid)
    except CheckpointError as err:
        ctx.log(f"cannot resume from {ckpt.name} ({err}); training from scratch")
        ckpt.unlink()
        return None
    if loaded.training_state is None:
        ckpt.unlink()
        return None
    ctx.log(f"resuming training after epoch {loaded.training_state['epoch']}")
    return ckpt


def _train_here(
    ctx: JobContext, data: Path, ckpt: Path, config: TrainConfig, resume: Path | None
) -> None:
    t0 = time.monotonic()
    first: list[int] = []

    def on_epoch(entry: dict[str, float]) -> None:
        epoch = int(entry["epoch"])
        if not first:
            first.append(epoch - 1)
        ctx.progress(
            JobProgress(
                fraction=epoch / max(config.epochs, 1),
                epoch=epoch,
                epochs=config.epochs,
                train_loss=entry["train_loss"],
                val_loss=entry["val_loss"],
                val_rel_l2=entry["val_rel_l2"],
                eta_s=eta_s(time.monotonic() - t0, epoch - first[0], config.epochs - first[0]),
            )
        )
        ctx.log(
            f"epoch {epoch}/{config.epochs}: train loss {entry['train_loss']:.4g}, "
            f"validation loss {entry['val_loss']:.4g}, relative L2 {entry['val_rel_l2']:.4g}"
        )

    train(data, ckpt, config, resume=resume, progress=False, on_epoch=on_epoch)


def _train_torchrun(
    ctx: JobContext, data: Path, ckpt: Path, config: TrainConfig, nproc: int, resume: Path | None
) -> None:
    cmd = torchrun_command(data, ckpt, config, nproc_per_node=nproc, resume=resume)
    ctx.log("running " + " ".join(cmd))
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert proc.stdout is not None
    for line in proc.stdout:
        ctx.log(line.rstrip())
    if proc.wait() != 0:
        raise CheckpointError(f"torchrun exited with code {proc.returncode}")


def _registered(ctx: JobContext) -> ModelInfo | None:
    """The model this job already registered (an attempt that died before finishing)."""
    return next((m for m in list_models(ctx.data_dir) if m.job_id == ctx.job.id), None)


def run_training_job(ctx: JobContext) -> dict[str, Any]:
    """Train (or resume), evaluate on the validation scenarios, register; returns the result."""
    spec = TrainingJobSpec.model_validate(ctx.job.spec)
    dataset_job = ctx.queue.get(spec.dataset)
    if dataset_job.state is not JobState.succeeded or dataset_job.result is None:
        raise CheckpointError(f"dataset: job {spec.dataset} has not succeeded")
    data = Path(dataset_job.result["dataset_path"])
    grid = tuple(int(n) for n in dataset_job.result["grid"])
    config = TrainConfig(**spec.train.model_dump())
    info = _registered(ctx)
    if info is None:
        folder = job_dir(ctx.data_dir, ctx.job.id)
        folder.mkdir(parents=True, exist_ok=True)
        ckpt = folder / CHECKPOINT
        resume = _resumable(ctx, ckpt, grid)  # type: ignore[arg-type]
        if spec.launcher == "torchrun":
            _train_torchrun(ctx, data, ckpt, config, spec.nproc_per_node, resume)
        else:
            _train_here(ctx, data, ckpt, config, resume)
        info = _register(ctx, spec, ckpt, data, dataset_job.result, config)
        ctx.log(f"registered model {info.ref}")
    if spec.activate:
        activate_model(ctx.data_dir, info.ref)
        ctx.log(f"activated {info.ref} for grid {'x'.join(map(str, info.grid))}")
    return {"model": info.ref, "model_path": str(info.path), "metrics": info.metrics}


def _register(
    ctx: JobContext,
    spec: TrainingJobSpec,
    ckpt: Path,
    data: Path,
    dataset_result: dict[str, Any],
    config: TrainConfig,
) -> ModelInfo:
    loaded = load_checkpoint(ckpt)
    val = tuple(int(s) for s in loaded.data.get("val_scenarios", ()))
    report = evaluate_model(loaded.model, data, scenarios=val)
    metrics = {**loaded.metrics, **{f"val_{k}": v for k, v in report.summary().items()}}
    n_params = sum(p.numel() for p in loaded.model.parameters())
    return register_model(
        ctx.data_dir,
        ckpt,
        name=spec.model_name,
        grid=loaded.grid_shape,
        architecture={
            "type": type(loaded.model).__name__,
            "width": config.width,
            "depth": config.depth,
            "parameters": int(n_params),
        },
        dataset_sha256=str(dataset_result["dataset_sha256"]),
        dataset={"job_id": spec.dataset, "path": str(data), "samples": dataset_result["samples"]},
        metrics=metrics,
        training={**asdict(config), "val_scenarios": list(val)},
        job_id=ctx.job.id,
        owner=ctx.job.owner,
    )
