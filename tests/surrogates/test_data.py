"""Reading the dataset file and splitting it by scenario."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from diathermy.errors import CheckpointError
from diathermy.surrogates.data import (
    FieldDataset,
    kfold_scenarios,
    read_dataset_info,
    split_scenarios,
)
from tests.surrogates.synthetic import write_synthetic_dataset


def test_header_and_samples(tiny_dataset: Path) -> None:
    info = read_dataset_info(tiny_dataset)
    assert info.grid_shape == (9, 9, 17) and info.n_samples == 24
    assert info.complete_scenarios() == (0, 1, 2, 3, 4, 5)
    np.testing.assert_array_equal(info.sample_indices((1, 3)), [4, 5, 6, 7, 12, 13, 14, 15])
    ds = FieldDataset(tiny_dataset, info.sample_indices((1,)))
    p, phi, u = ds[2]
    assert p.shape == phi.shape == (9, 9, 17) and u.shape == (3, 9, 9, 17)
    with h5py.File(tiny_dataset) as f:
        np.testing.assert_array_equal(u.numpy(), np.moveaxis(f["displacement"][6], -1, 0))
        np.testing.assert_array_equal(p.numpy(), f["pressure"][6])


def test_incomplete_scenarios_are_never_used(tmp_path: Path) -> None:
    path = write_synthetic_dataset(
        tmp_path / "d.h5", n_scenarios=3, n_steps=2, incomplete_last=True
    )
    assert read_dataset_info(path).complete_scenarios() == (0, 1)


def test_generator_layout_with_commit_marker(tmp_path: Path) -> None:
    """The generator's layout: no /scenarios table, rows past ``complete_rows`` are partial."""
    path = write_synthetic_dataset(tmp_path / "d.h5", n_scenarios=3, n_steps=2)
    with h5py.File(path, "a") as f:
        del f["scenarios"]
        del f.attrs["material"]
        f.attrs["config"] = json.dumps({"material": {"p_atm_pa": 100000.0}})
        f.attrs.update(complete_scenarios=2, complete_rows=4, p0_pa=100000.0)
    info = read_dataset_info(path)
    assert info.n_samples == 4 and info.complete_scenarios() == (0, 1)
    assert info.p0_pa == 100000.0 and info.material == {"p_atm_pa": 100000.0}


def test_foreign_and_missing_files(tmp_path: Path) -> None:
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f.attrs["format"] = "diathermy-run"
    text = tmp_path / "text.h5"
    text.write_text("hello")
    for path, message in [(other, "not a diathermy dataset"), (text, "not a readable HDF5"),
                          (tmp_path / "none.h5", "does not exist")]:  # fmt: skip
        with pytest.raises(CheckpointError, match=message):
            read_dataset_info(path)


@given(
    n=st.integers(2, 40),
    fraction=st.floats(0.01, 0.99),
    seed=st.integers(0, 2**31),
)
def test_scenario_split_is_a_partition(n: int, fraction: float, seed: int) -> None:
    ids = list(range(100, 100 + n))
    train, val = split_scenarios(ids, fraction, seed)
    assert set(train).isdisjoint(val) and sorted(train + val) == ids
    assert train and val
    assert (train, val) == split_scenarios(ids, fraction, seed)


def test_split_refuses_a_single_scenario() -> None:
    with pytest.raises(CheckpointError, match="at least 2"):
        split_scenarios([0], 0.2, 0)


@given(n=st.integers(2, 30), k=st.integers(2, 30), seed=st.integers(0, 1000))
def test_kfold_holds_out_every_scenario_exactly_once(n: int, k: int, seed: int) -> None:
    ids = list(range(n))
    if k > n:
        with pytest.raises(CheckpointError, match="folds"):
            kfold_scenarios(ids, k, seed)
        return
    folds = kfold_scenarios(ids, k, seed)
    held = [s for _, h in folds for s in h]
    assert sorted(held) == ids
    for train, h in folds:
        assert set(train).isdisjoint(h) and sorted(train + h) == ids
