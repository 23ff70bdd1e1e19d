"""Evaluation of a trained CNN and K-fold cross-validation by scenario."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from diathermy.surrogates import CNNConfig, DisplacementCNN, predict
from diathermy.surrogates.data import read_dataset_info, read_samples
from diathermy.surrogates.evaluation import cross_validate, evaluate_model
from diathermy.surrogates.train_config import TrainConfig


def _energy_proxy(u: np.ndarray, u_ref: np.ndarray, p: np.ndarray, phi: np.ndarray) -> float:
    """A stand-in strain-energy error: relative error of sum |u|^2 (enough to test plumbing)."""
    return abs(float(np.sum(u**2)) - float(np.sum(u_ref**2))) / float(np.sum(u_ref**2))


def test_errors_per_sample_match_a_direct_computation(tiny_dataset: Path) -> None:
    torch.manual_seed(0)
    model = DisplacementCNN(CNNConfig(width=4, depth=2))
    report = evaluate_model(
        model, tiny_dataset, scenarios=(1, 4), batch_size=3, strain_energy_error=_energy_proxy
    )
    info = read_dataset_info(tiny_dataset)
    rows = info.sample_indices((1, 4))
    np.testing.assert_array_equal(report.sample, rows)
    np.testing.assert_array_equal(report.scenario, [1] * 4 + [4] * 4)
    p, phi, u = read_samples(tiny_dataset, rows)
    for k in range(rows.size):  # slow reference twin, one sample at a time
        pred = predict(model, p[k], phi[k])
        rel = np.linalg.norm(pred - u[k]) / np.linalg.norm(u[k])
        np.testing.assert_allclose(report.displacement_rel_l2[k], rel, rtol=1e-5)
        np.testing.assert_allclose(
            report.displacement_max_abs_m[k], np.abs(pred - u[k]).max(), rtol=1e-5
        )
        np.testing.assert_allclose(
            report.strain_energy_error[k], _energy_proxy(pred, u[k], p[k], phi[k])
        )
    summary = report.summary()
    assert summary["samples"] == 8
    assert summary["mean_strain_energy_error"] == np.mean(report.strain_energy_error)


def test_cross_validation_holds_out_each_scenario_once(tiny_dataset: Path, tmp_path: Path) -> None:
    cfg = TrainConfig(width=4, depth=2, epochs=1, batch_size=4, seed=3)
    cv = cross_validate(tiny_dataset, 3, cfg, work_dir=tmp_path, strain_energy_error=_energy_proxy)
    held = sorted(s for h in cv.held_out for s in h)
    assert held == list(range(6)) and len(cv.folds) == 3
    for h, report in zip(cv.held_out, cv.folds, strict=True):
        assert set(report.scenario) == set(h)
    assert sum(r.sample.size for r in cv.folds) == 24
    assert np.isfinite(cv.mean_strain_energy_error)
    assert cv.max_strain_energy_error >= cv.mean_strain_energy_error
    # each fold's model never saw its held-out scenarios, not even for early stopping
    from diathermy.surrogates import load_checkpoint

    for i, h in enumerate(cv.held_out):
        data = load_checkpoint(tmp_path / f"fold{i}.pt").data
        assert set(h).isdisjoint(data["train_scenarios"] + data["val_scenarios"])
    assert replace(cfg).epochs == 1


def test_baseline_scores_persistence_beside_the_network(tiny_dataset: Path) -> None:
    from diathermy.surrogates.baseline import baseline_report

    torch.manual_seed(0)
    model = DisplacementCNN(CNNConfig(width=4, depth=2))
    report = baseline_report(model, tiny_dataset, scenarios=(1, 4))
    s = report.scores
    assert [len(s[n]) for n in ("cnn", "cnn+patch", "previous", "previous+patch")] == [8, 8, 6, 6]
    for alone, patched in zip(s["previous"], s["previous+patch"], strict=True):
        assert patched.residual <= alone.residual + 1e-12  # the patch never moves away
    assert report.summary()["previous"]["samples"] == 6
