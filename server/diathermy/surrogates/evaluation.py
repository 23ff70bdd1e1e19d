"""Errors of a trained CNN on held-out scenarios, and K-fold cross-validation by scenario.

The strain-energy error is the paper's eq. 20/21 measure, computed by the mechanics' own numpy
functions (``diathermy.physics.strain_energy`` through ``diathermy.physics.strain_energy_error``);
this module only runs the network and collects numbers.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import h5py
import numpy as np
import torch

from diathermy.surrogates.checkpoint import load_checkpoint
from diathermy.surrogates.cnn import DisplacementCNN
from diathermy.surrogates.data import DatasetInfo, kfold_scenarios, read_dataset_info, read_samples
from diathermy.surrogates.inference import predict
from diathermy.surrogates.train_config import TrainConfig
from diathermy.surrogates.training import train

# (u_pred (nz, ny, nx, 3) m, u_ref (same) m, pressure (nz, ny, nx) Pa, level set (nz, ny, nx) m)
#   -> relative strain-energy error of u_pred against u_ref
StrainEnergyError = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], float]


@dataclass(frozen=True)
class EvaluationReport:
    """Per-sample errors (arrays of shape (S,)) and their summaries."""

    sample: np.ndarray  # row in the dataset file
    scenario: np.ndarray
    strain_energy_error: np.ndarray  # relative, eq. 20/21 (NaN when not computed)
    displacement_rel_l2: np.ndarray  # ||u - u_ref|| / ||u_ref||
    displacement_max_abs_m: np.ndarray  # max |u - u_ref| over nodes and components, m

    @property
    def mean_strain_energy_error(self) -> float:
        return float(np.mean(self.strain_energy_error)) if self.sample.size else float("nan")

    @property
    def max_strain_energy_error(self) -> float:
        return float(np.max(self.strain_energy_error)) if self.sample.size else float("nan")

    @property
    def mean_displacement_rel_l2(self) -> float:
        return float(np.mean(self.displacement_rel_l2)) if self.sample.size else float("nan")

    @property
    def max_displacement_abs_m(self) -> float:
        return float(np.max(self.displacement_max_abs_m)) if self.sample.size else float("nan")

    def summary(self) -> dict[str, float]:
        """The headline numbers as a flat dict."""
        return {
            "samples": float(self.sample.size),
            "mean_strain_energy_error": self.mean_strain_energy_error,
            "max_strain_energy_error": self.max_strain_energy_error,
            "mean_displacement_rel_l2": self.mean_displacement_rel_l2,
            "max_displacement_abs_m": self.max_displacement_abs_m,
        }


def default_strain_energy_error(info: DatasetInfo) -> StrainEnergyError:
    """The mechanics' strain-energy error on the dataset's grid and material (numpy, no torch)."""
    from diathermy.physics.strain_energy_error import strain_energy_error_on_grid

    return strain_energy_error_on_grid(info.grid_shape, info.spacing_m, info.material)


def evaluate_model(
    model: DisplacementCNN,
    data_path: str | os.PathLike[str],
    *,
    scenarios: tuple[int, ...] | None = None,
    batch_size: int = 4,
    strain_energy_error: StrainEnergyError | None = None,
) -> EvaluationReport:
    """Errors of ``model`` on every sample of ``scenarios`` (default: all complete ones)."""
    info = read_dataset_info(data_path)
    chosen = info.complete_scenarios() if scenarios is None else scenarios
    rows = info.sample_indices(chosen)
    se = strain_energy_error or default_strain_energy_error(info)
    with h5py.File(info.path, "r") as f:
        scen = (
            np.asarray(f["scenario"][...], np.int64)[rows]
            if "scenario" in f
            else np.zeros_like(rows)
        )
    out: dict[str, list[float]] = {"se": [], "rel": [], "max": []}
    model.eval()
    for start in range(0, rows.size, batch_size):
        p, phi, u_ref = read_samples(info.path, rows[start : start + batch_size])
        u_pred = predict(model, p, phi)
        for i in range(p.shape[0]):
            diff = (u_pred[i] - u_ref[i]).astype(np.float64)
            ref_norm = float(np.linalg.norm(u_ref[i]))
            out["rel"].append(
                float(np.linalg.norm(diff)) / ref_norm
                if ref_norm > 0
                else float(np.linalg.norm(diff))
            )
            out["max"].append(float(np.max(np.abs(diff))))
            out["se"].append(float(se(u_pred[i], u_ref[i], p[i], phi[i])))
    return EvaluationReport(
        sample=rows,
        scenario=scen,
        strain_energy_error=np.asarray(out["se"]),
        displacement_rel_l2=np.asarray(out["rel"]),
        displacement_max_abs_m=np.asarray(out["max"]),
    )


@dataclass(frozen=True)
class CrossValidationReport:
    """K folds by scenario: the held-out scenarios and the report of each fold's model."""

    held_out: tuple[tuple[int, ...], ...]
    folds: tuple[EvaluationReport, ...]

    @property
    def mean_strain_energy_error(self) -> float:
        """Mean over every held-out sample of every fold (each sample held out exactly once)."""
        return float(np.mean(np.concatenate([r.strain_energy_error for r in self.folds])))

    @property
    def max_strain_energy_error(self) -> float:
        return float(np.max(np.concatenate([r.strain_energy_error for r in self.folds])))


def cross_validate(
    data_path: str | os.PathLike[str],
    k: int,
    config: TrainConfig,
    *,
    work_dir: str | os.PathLike[str] | None = None,
    progress: bool = False,
    strain_energy_error: StrainEnergyError | None = None,
) -> CrossValidationReport:
    """Train one model per fold on the other K-1 folds' scenarios and evaluate it on its own.

    Early stopping inside a fold uses a validation split of that fold's training scenarios
    (``config.val_fraction``), so the held-out fold never steers training.
    """
    from diathermy.surrogates.data import split_scenarios

    info = read_dataset_info(data_path)
    folds = kfold_scenarios(info.complete_scenarios(), k, config.seed)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(work_dir) if work_dir is not None else Path(tmp)
        reports = []
        for i, (train_s, held) in enumerate(folds):
            inner = split_scenarios(train_s, config.val_fraction, config.seed + i)
            out = root / f"fold{i}.pt"
            train(
                info.path,
                out,
                replace(config, seed=config.seed + i),
                split=inner,
                progress=progress,
            )
            model = load_checkpoint(out).model
            if torch.cuda.is_available():
                model.cuda()
            reports.append(
                evaluate_model(
                    model, info.path, scenarios=held, batch_size=config.batch_size,
                    strain_energy_error=strain_energy_error,
                )
            )  # fmt: skip
    return CrossValidationReport(tuple(held for _, held in folds), tuple(reports))
