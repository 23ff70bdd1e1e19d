"""Fixtures for the surrogate tests: tiny synthetic datasets in the agreed HDF5 format."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from tests.surrogates.synthetic import write_synthetic_dataset

torch.set_num_threads(1)  # small tensors: threads only add noise on shared 2-core machines


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """6 scenarios x 4 steps on a 9x9x17 grid."""
    return write_synthetic_dataset(tmp_path_factory.mktemp("data") / "tiny.h5")
