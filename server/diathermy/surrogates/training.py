"""Training loop of the CNN: Adam on the L2 displacement error, scenario-wise validation, early
stopping, resumable checkpoints, mixed precision and ``torch.distributed`` data parallelism.

Launch data-parallel runs with ``torchrun --nproc_per_node N -m diathermy train ...``; the
process group is set up from the environment torchrun provides (NCCL on GPUs, gloo on CPUs).
"""

from __future__ import annotations

import contextlib
import copy
import math
import os
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.distributed as dist
from torch.nn.parallel import DistributedDataParallel
from torch.utils.data import DataLoader, DistributedSampler
from tqdm import tqdm

from diathermy.errors import CheckpointError
from diathermy.physics.strain_energy_error import dataset_tissue
from diathermy.surrogates.checkpoint import LoadedCheckpoint, load_checkpoint, save_checkpoint
from diathermy.surrogates.cnn import DisplacementCNN
from diathermy.surrogates.data import (
    DatasetInfo,
    FieldDataset,
    read_dataset_info,
    read_samples,
    split_scenarios,
)
from diathermy.surrogates.devices import DistInfo, deterministic, init_distributed, resolve_device
from diathermy.surrogates.losses import relative_l2_per_sample, training_loss
from diathermy.surrogates.normalization import fit_scales
from diathermy.surrogates.strain_energy import GridStrainEnergy
from diathermy.surrogates.train_config import AMP_DTYPES, TrainConfig, TrainResult, learning_rate


@dataclass(frozen=True)
class _Start:
    """Where a run starts: the model, a resumed run's training state, the fine-tune lineage."""

    model: DisplacementCNN
    training_state: dict[str, Any] | None
    lineage: dict[str, Any] | None


def _batches(
    dataset: FieldDataset, batch_size: int, sampler: DistributedSampler | None, workers: int
) -> DataLoader:
    return DataLoader(
        dataset, batch_size=batch_size, sampler=sampler, shuffle=False, num_workers=workers
    )


def _scale_indices(indices: np.ndarray, n: int) -> np.ndarray:
    if indices.size <= n:
        return indices
    return indices[np.linspace(0, indices.size - 1, n).round().astype(np.int64)]


LossFn = Callable[[torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor]


def loss_function(config: TrainConfig, info: DatasetInfo, device: torch.device) -> LossFn:
    """(prediction, target in network units, level set m) -> the configured training loss."""
    energy = None
    if config.energy_weight > 0:
        tissue = dataset_tissue(info.material)
        energy = GridStrainEnergy(
            info.spacing_m, tissue.poisson_ratio, tissue.ersatz_stiffness_ratio
        ).to(device)

    def loss(pred: torch.Tensor, target: torch.Tensor, level_set: torch.Tensor) -> torch.Tensor:
        return training_loss(
            pred, target, config.strain_weight, config.energy_weight, energy, level_set
        )

    return loss


def _evaluate_loss(
    model: torch.nn.Module,
    net: DisplacementCNN,
    loader: DataLoader,
    device: torch.device,
    autocast: Callable[[], contextlib.AbstractContextManager[Any]],
    loss_fn: LossFn,
) -> tuple[float, float]:
    """(mean training loss, mean relative L2 error of u) over a loader."""
    model.eval()
    total, rel, count = 0.0, 0.0, 0
    with torch.inference_mode():
        for p, phi, u in loader:
            p, phi, u = p.to(device), phi.to(device), u.to(device)
            with autocast():
                pred = model(net.normalizer.encode_inputs(p, phi)).float()
            target = net.normalizer.encode_displacement(u, p)
            total += float(loss_fn(pred, target, phi)) * p.shape[0]
            rel += float(relative_l2_per_sample(pred, target).sum())
            count += p.shape[0]
    return total / max(count, 1), rel / max(count, 1)


def _start_state(
    info: DatasetInfo,
    config: TrainConfig,
    resume: str | os.PathLike[str] | None,
    split: tuple[tuple[int, ...], tuple[int, ...]] | None,
    init_from: str | os.PathLike[str] | None = None,
) -> tuple[_Start, tuple[tuple[int, ...], tuple[int, ...]]]:
    """The model to train (fresh, resumed or initialised from a checkpoint's weights and
    normaliser), the resumed training state and lineage, the scenario split."""
    if resume is not None:
        ckpt = load_checkpoint(resume, expected_grid=info.grid_shape)
        if ckpt.training_state is None:
            raise CheckpointError(f"{str(resume)!r} holds no training state to resume from")
        model = ckpt.model
        model.load_state_dict(ckpt.training_state["model_state"])
        train_s = tuple(int(s) for s in ckpt.data.get("train_scenarios", ()))
        val_s = tuple(int(s) for s in ckpt.data.get("val_scenarios", ()))
        return _Start(model, ckpt.training_state, ckpt.data.get("init_from")), (train_s, val_s)
    if split is None:
        split = split_scenarios(info.complete_scenarios(), config.val_fraction, config.seed)
    if init_from is not None:
        parent = load_checkpoint(init_from, expected_grid=info.grid_shape)
        model = parent.model
        if (model.config.arch, model.config.levels) != (config.arch, config.levels):
            raise CheckpointError(
                f"{str(init_from)!r} has arch {model.config.arch!r} with {model.config.levels} "
                f"levels, the run asks for {config.arch!r} with {config.levels} (they must match)"
            )
        if model.config.arch != "pooled" and (
            config.width != model.config.width or config.mask_input != model.config.mask_input
        ):
            raise CheckpointError(
                f"{str(init_from)!r} is a {model.config.arch}: only the paper's layout can be "
                "widened or given the mask channel; fine-tune it at its own width and inputs"
            )
        arch = (model.config.width, model.config.depth)
        if model.config.depth != config.depth or model.config.width > config.width:
            raise CheckpointError(
                f"{str(init_from)!r} has width/depth {arch}, the run asks for "
                f"{(config.width, config.depth)} (the depth must match; the width may grow)"
            )
        if model.normalizer.per_sample_amplitude != config.per_sample_amplitude:
            raise CheckpointError(
                f"{str(init_from)!r} has per_sample_amplitude="
                f"{model.normalizer.per_sample_amplitude}, the run asks for the other"
            )
        if model.config.mask_input and not config.mask_input:
            raise CheckpointError(
                f"{str(init_from)!r} reads the tissue mask; the run asks for a model without it "
                "(add --mask-input)"
            )
        if config.mask_input:
            model = model.with_mask_input()  # a parent without the mask gains a zero channel
        if config.width > model.config.width:
            model = model.widened(config.width, seed=config.seed)  # Net2WiderNet copies
        return _Start(model, None, init_record(init_from, parent)), split
    p, phi, u = read_samples(
        info.path, _scale_indices(info.sample_indices(split[0]), config.scale_samples)
    )
    p0 = info.p0_pa
    torch.manual_seed(config.seed)
    model = DisplacementCNN(
        config.model_config(),
        fit_scales(p, phi, u, p0_pa=p0, per_sample_amplitude=config.per_sample_amplitude),
    )
    return _Start(model, None, None), split


def init_record(path: str | os.PathLike[str], parent: LoadedCheckpoint) -> dict[str, Any]:
    """Where a fine-tuned model's starting weights came from: the parent's file, data, config,
    metrics and (recursively) its own parent, so a chain of fine-tunes stays traceable."""
    return {
        "path": str(path),
        "data_path": parent.data.get("path"),
        "training_config": parent.training_config,
        "metrics": parent.metrics,
        "init_from": parent.data.get("init_from"),
    }


def train(
    data_path: str | os.PathLike[str],
    out_path: str | os.PathLike[str],
    config: TrainConfig,
    *,
    resume: str | os.PathLike[str] | None = None,
    split: tuple[tuple[int, ...], tuple[int, ...]] | None = None,
    init_from: str | os.PathLike[str] | None = None,
    progress: bool = True,
    on_epoch: Callable[[dict[str, float]], None] | None = None,
) -> TrainResult:
    """Train a CNN on a dataset file and write the best model (by validation loss) to ``out_path``.

    ``split`` = (train scenarios, validation scenarios) overrides the seeded random split (used by
    cross-validation); ``resume`` continues a checkpoint written by this function (same split,
    same normaliser, its optimizer state and epoch counter); ``init_from`` starts from another
    checkpoint's weights and normaliser (fine-tuning on new data: fresh optimizer, this dataset's
    split; the architecture must match ``config``). ``on_epoch(history entry)`` runs on
    the main rank after each epoch's checkpoint is written (progress; an exception from it stops
    training with that checkpoint kept, resumable).
    """
    info = read_dataset_info(data_path)
    want_cuda = config.device.startswith("cuda") or (
        config.device == "auto" and torch.cuda.is_available()
    )
    amp_dtype = AMP_DTYPES[config.amp]
    device = resolve_device(config.device, int(os.environ.get("LOCAL_RANK", "0")))
    if amp_dtype is torch.float16 and device.type != "cuda":
        raise CheckpointError("fp16 mixed precision needs a CUDA device; use --amp bf16 on CPU")
    owns_group = not (dist.is_available() and dist.is_initialized())
    ctx = init_distributed("cuda" if want_cuda else "cpu")
    if device.type == "cuda":
        torch.cuda.set_device(device)
    try:
        with deterministic(device.type == "cpu"):
            return _train(
                info,
                Path(out_path),
                config,
                ctx,
                device,
                amp_dtype,
                resume,
                split,
                init_from,
                progress,
                on_epoch,
            )
    finally:
        if ctx.active and owns_group:
            dist.destroy_process_group()


def _train(
    info: DatasetInfo,
    out_path: Path,
    config: TrainConfig,
    ctx: DistInfo,
    device: torch.device,
    amp_dtype: torch.dtype | None,
    resume: str | os.PathLike[str] | None,
    split: tuple[tuple[int, ...], tuple[int, ...]] | None,
    init_from: str | os.PathLike[str] | None,
    progress: bool,
    on_epoch: Callable[[dict[str, float]], None] | None = None,
) -> TrainResult:
    if resume is not None and init_from is not None:
        raise CheckpointError("resume and init_from exclude each other")
    if resume is not None and split is not None:
        raise CheckpointError("a resumed run keeps its checkpoint's scenario split; give no split")
    start, (train_s, val_s) = _start_state(info, config, resume, split, init_from)
    net, state = start.model, start.training_state
    if set(train_s) & set(val_s) or not train_s or not val_s:
        raise CheckpointError(f"bad scenario split: train {train_s}, validation {val_s}")
    net.to(device)
    model: torch.nn.Module = net
    if ctx.active:
        model = DistributedDataParallel(
            net, device_ids=[device.index] if device.type == "cuda" else None
        )
    optimizer = torch.optim.Adam(net.parameters(), lr=config.lr)
    scaler = torch.amp.GradScaler("cuda", enabled=amp_dtype is torch.float16)
    start_epoch, best_val, best_rel, best_epoch, bad = 0, math.inf, math.inf, -1, 0
    history: list[dict[str, float]] = []
    best_weights = copy.deepcopy(net.state_dict())
    if state is not None:
        optimizer.load_state_dict(state["optimizer_state"])
        if "scaler_state" in state and scaler.is_enabled():
            scaler.load_state_dict(state["scaler_state"])
        start_epoch, bad = int(state["epoch"]), int(state["bad_epochs"])
        best_val, best_rel = float(state["best_val_loss"]), float(state["best_val_rel_l2"])
        best_epoch = int(state["best_epoch"])
        history = [dict(h) for h in state["history"]]
        best_weights = load_checkpoint(resume).model.state_dict()  # type: ignore[arg-type]

    train_ds = FieldDataset(info.path, info.sample_indices(train_s))
    val_ds = FieldDataset(info.path, info.sample_indices(val_s))
    sampler: DistributedSampler[Any] = DistributedSampler(
        train_ds, num_replicas=ctx.world_size, rank=ctx.rank, shuffle=True, seed=config.seed
    )
    train_loader = _batches(train_ds, config.batch_size, sampler, config.num_workers)
    val_loader = _batches(val_ds, config.batch_size, None, config.num_workers)

    def autocast() -> contextlib.AbstractContextManager[Any]:
        if amp_dtype is None:
            return contextlib.nullcontext()
        return torch.autocast(device_type=device.type, dtype=amp_dtype)

    planned_steps = config.epochs * len(train_loader)
    loss_fn = loss_function(config, info, device)
    total_steps = max(config.epochs - start_epoch, 0) * len(train_loader)
    bar = tqdm(
        total=total_steps, disable=not (progress and ctx.is_main), unit="batch", dynamic_ncols=True
    )
    epoch, stopped = start_epoch, bad >= config.patience
    try:
        for epoch in range(start_epoch, config.epochs):
            if stopped:
                break
            t0 = time.perf_counter()
            sampler.set_epoch(epoch)
            model.train()
            running, seen = 0.0, 0
            for i, (p, phi, u) in enumerate(train_loader):
                p, phi, u = p.to(device), phi.to(device), u.to(device)
                progress_done = (epoch * len(train_loader) + i) / max(planned_steps, 1)
                for group in optimizer.param_groups:
                    group["lr"] = learning_rate(config.lr, config.lr_schedule, progress_done)
                optimizer.zero_grad(set_to_none=True)
                with autocast():
                    pred = model(net.normalizer.encode_inputs(p, phi))
                target = net.normalizer.encode_displacement(u, p)
                loss = loss_fn(pred, target, phi)
                scaler.scale(loss).backward()
                scaler.step(optimizer)
                scaler.update()
                running += float(loss.detach()) * p.shape[0]
                seen += p.shape[0]
                bar.update(1)
                bar.set_postfix(
                    epoch=epoch + 1, loss=f"{running / seen:.4g}", val=f"{best_val:.4g}"
                )
            val_loss, val_rel = _evaluate_loss(model, net, val_loader, device, autocast, loss_fn)
            if val_loss < best_val:
                best_val, best_rel, best_epoch, bad = val_loss, val_rel, epoch + 1, 0
                best_weights = copy.deepcopy(net.state_dict())
            else:
                bad += 1
            stopped = bad >= config.patience
            history.append(
                {
                    "epoch": float(epoch + 1),
                    "train_loss": running / max(seen, 1),
                    "val_loss": val_loss,
                    "val_rel_l2": val_rel,
                    "seconds": time.perf_counter() - t0,
                }
            )
            if ctx.is_main:
                _save(
                    out_path,
                    net,
                    best_weights,
                    info,
                    config,
                    train_s,
                    val_s,
                    start.lineage,
                    {
                        "epoch": epoch + 1,
                        "model_state": {
                            k: v.detach().cpu().clone() for k, v in net.state_dict().items()
                        },
                        "optimizer_state": optimizer.state_dict(),
                        "scaler_state": scaler.state_dict(),
                        "best_val_loss": best_val,
                        "best_val_rel_l2": best_rel,
                        "best_epoch": best_epoch,
                        "bad_epochs": bad,
                        "history": history,
                    },
                )
            if ctx.active:
                dist.barrier()
            if on_epoch is not None and ctx.is_main:
                on_epoch(dict(history[-1]))  # after the save: a stop here loses no epoch
    finally:
        bar.close()
    if ctx.is_main and not history and resume is None:  # epochs=0: still write a usable model
        _save(out_path, net, best_weights, info, config, train_s, val_s, start.lineage, None)
    epochs_run = len(history)
    return TrainResult(
        checkpoint=out_path,
        epochs_run=epochs_run,
        best_epoch=best_epoch,
        best_val_loss=best_val,
        best_val_rel_l2=best_rel,
        stopped_early=stopped,
        history=tuple(history),
        train_scenarios=train_s,
        val_scenarios=val_s,
    )


def _save(
    out_path: Path,
    net: DisplacementCNN,
    best_weights: dict[str, torch.Tensor],
    info: DatasetInfo,
    config: TrainConfig,
    train_s: tuple[int, ...],
    val_s: tuple[int, ...],
    lineage: dict[str, Any] | None,
    training_state: dict[str, Any] | None,
) -> None:
    """Checkpoint whose weights are the best so far and whose training state is the latest."""
    best = DisplacementCNN.from_constructor_args(net.constructor_args())
    best.load_state_dict(best_weights)
    metrics: dict[str, Any] = {}
    if training_state is not None:
        metrics = {
            "best_val_loss": training_state["best_val_loss"],
            "best_val_rel_l2": training_state["best_val_rel_l2"],
            "best_epoch": training_state["best_epoch"],
            "epochs_run": training_state["epoch"],
        }
    save_checkpoint(
        out_path,
        best,
        grid_shape=info.grid_shape,
        spacing_m=info.spacing_m,
        training_config=asdict(config),
        metrics=metrics,
        data={
            "path": str(info.path),
            "train_scenarios": list(train_s),
            "val_scenarios": list(val_s),
            **({"init_from": lineage} if lineage is not None else {}),
        },
        training_state=training_state,
    )
