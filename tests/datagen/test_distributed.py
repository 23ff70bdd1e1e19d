"""The Dask engine on a local cluster of 2 worker processes writes the local engine's file."""

from __future__ import annotations

from pathlib import Path

import cloudpickle

import tests.datagen.fakes as fakes
from diathermy.datagen import DatagenConfig, generate
from tests.datagen.helpers import assert_same_contents


def test_dask_local_cluster_matches_the_local_engine(
    tmp_path: Path, tiny_config: DatagenConfig
) -> None:
    cloudpickle.register_pickle_by_value(fakes)  # spawned workers cannot import tests/
    try:
        generate(tiny_config, tmp_path / "local.h5", factory=fakes.analytic_physics)
        summary = generate(
            tiny_config,
            tmp_path / "dask.h5",
            factory=fakes.analytic_physics,
            engine="dask",
            workers=2,
        )
    finally:
        cloudpickle.unregister_pickle_by_value(fakes)
    assert summary.engine == "dask" and summary.computed_scenarios == 4
    assert_same_contents(tmp_path / "local.h5", tmp_path / "dask.h5")
