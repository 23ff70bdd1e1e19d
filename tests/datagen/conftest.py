"""Small configs for the datagen tests."""

from __future__ import annotations

import pytest

from diathermy.datagen.config import DatagenConfig


@pytest.fixture()
def tiny_config() -> DatagenConfig:
    """5x5x9 nodes, 4 scenarios of 6 steps, float64 storage."""
    return DatagenConfig(
        grid=(5, 5, 9), n_scenarios=4, n_steps=6, seed=7, dtype="float64", p_max_pa=6.0e5
    )
