"""Surrogates of the mechanics; the only package that imports torch.

layers -> cnn (model) -> losses -> training, apart; ``checkpoint`` rebuilds exactly what was
trained, ``data`` reads the HDF5 dataset with scenario-wise splits, ``evaluation`` measures errors.
Names load lazily, so ``import diathermy.surrogates.cli`` (argument parsing) does not import torch.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "CNNConfig": "diathermy.surrogates.cnn",
    "DisplacementCNN": "diathermy.surrogates.cnn",
    "FieldScales": "diathermy.surrogates.normalization",
    "LoadedCheckpoint": "diathermy.surrogates.checkpoint",
    "load_checkpoint": "diathermy.surrogates.checkpoint",
    "save_checkpoint": "diathermy.surrogates.checkpoint",
    "predict": "diathermy.surrogates.inference",
    "TrainConfig": "diathermy.surrogates.train_config",
    "train": "diathermy.surrogates.training",
    "evaluate_model": "diathermy.surrogates.evaluation",
    "cross_validate": "diathermy.surrogates.evaluation",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module 'diathermy.surrogates' has no attribute {name!r}")
    return getattr(importlib.import_module(_EXPORTS[name]), name)


def __dir__() -> list[str]:
    return __all__
