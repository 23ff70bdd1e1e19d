"""Hyper-parameters of a CNN training run, its result, and the learning-rate schedule."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import torch

from diathermy.errors import CheckpointError
from diathermy.surrogates.cnn import CNNConfig

AMP_DTYPES = {"none": None, "bf16": torch.bfloat16, "fp16": torch.float16}
LR_SCHEDULES = ("constant", "cosine")
COSINE_FLOOR = 0.01  # the cosine schedule ends at this fraction of the initial learning rate


def learning_rate(lr: float, schedule: str, progress: float) -> float:
    """The learning rate at ``progress`` in [0, 1] of the planned epochs (a pure function of it,
    so a resumed run continues the same curve): constant, or a half cosine from lr to lr/100."""
    if schedule == "constant":
        return lr
    t = min(max(progress, 0.0), 1.0)
    return lr * (COSINE_FLOOR + (1.0 - COSINE_FLOOR) * 0.5 * (1.0 + math.cos(math.pi * t)))


@dataclass(frozen=True)
class TrainConfig:
    """Hyper-parameters of one training run (stored in the checkpoint)."""

    width: int = 16
    depth: int = 5
    epochs: int = 50
    batch_size: int = 4
    lr: float = 1e-3
    val_fraction: float = 0.2
    patience: int = 10
    seed: int = 0
    amp: str = "none"  # "none", "bf16" or "fp16" (fp16 needs CUDA)
    device: str = "auto"  # "auto", "cpu", "cuda", "cuda:1", ...
    num_workers: int = 0
    scale_samples: int = 256  # training samples used to fit the normaliser
    per_sample_amplitude: bool = True  # input/output scaled by each sample's max |p - p0|
    strain_weight: float = 1.0  # weight of the displacement-difference (strain) loss
    lr_schedule: str = "constant"  # "constant", or "cosine": lr decays to lr/100 over the epochs
    energy_weight: float = 0.0  # weight of the squared relative strain-energy error (eq. 20/21)
    mask_input: bool = False  # the tissue mask phi > 0 as a third input channel
    arch: str = "pooled"  # the network's body: "pooled" (the paper's) or "unet"
    levels: int = 4  # the U-Net's levels (arch "unet")

    def __post_init__(self) -> None:
        checks = {
            "epochs": self.epochs >= 0,
            "batch_size": self.batch_size >= 1,
            "lr": math.isfinite(self.lr) and self.lr > 0,
            "patience": self.patience >= 1,
            "num_workers": self.num_workers >= 0,
            "scale_samples": self.scale_samples >= 1,
            "strain_weight": math.isfinite(self.strain_weight) and self.strain_weight >= 0,
            "energy_weight": math.isfinite(self.energy_weight) and self.energy_weight >= 0,
        }
        for name, ok in checks.items():
            if not ok:
                raise CheckpointError(f"training option {name} is invalid: {getattr(self, name)!r}")
        if self.amp not in AMP_DTYPES:
            raise CheckpointError(f"amp must be one of {sorted(AMP_DTYPES)}, got {self.amp!r}")
        if self.lr_schedule not in LR_SCHEDULES:
            raise CheckpointError(
                f"lr_schedule must be one of {list(LR_SCHEDULES)}, got {self.lr_schedule!r}"
            )
        try:
            self.model_config()
        except ValueError as err:
            raise CheckpointError(f"training option arch/levels is invalid: {err}") from None

    def model_config(self) -> CNNConfig:
        """The network these options build."""
        return CNNConfig(
            width=self.width,
            depth=self.depth,
            mask_input=self.mask_input,
            arch=self.arch,
            levels=self.levels,
        )


@dataclass(frozen=True)
class TrainResult:
    """What a run did: where the best model went, and the per-epoch history."""

    checkpoint: Path
    epochs_run: int
    best_epoch: int
    best_val_loss: float
    best_val_rel_l2: float
    stopped_early: bool
    history: tuple[dict[str, float], ...]
    train_scenarios: tuple[int, ...]
    val_scenarios: tuple[int, ...]
