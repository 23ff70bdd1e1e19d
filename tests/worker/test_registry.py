"""The model registry: versions, metadata, activation per grid, resolve_model."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from diathermy.worker.registry import (
    ModelNotFoundError,
    activate_model,
    get_model,
    list_models,
    register_model,
    resolve_model,
)


def _register(data: Path, tmp: Path, name: str, grid: tuple[int, int, int]) -> str:
    ckpt = tmp / "ckpt.pt"
    ckpt.write_bytes(b"weights")
    info = register_model(
        data,
        ckpt,
        name=name,
        grid=grid,
        architecture={"width": 4},
        dataset_sha256="ab" * 32,
        dataset={"job_id": "j-1"},
        metrics={"val_mean_strain_energy_error": 0.1},
        training={"epochs": 1},
    )
    return info.ref


def test_versions_metadata_activation_and_resolution(tmp_path: Path) -> None:
    data = tmp_path / "data"
    assert resolve_model(data, (5, 5, 9)) is None
    assert _register(data, tmp_path, "cnn", (5, 5, 9)) == "cnn:1"
    assert _register(data, tmp_path, "cnn", (5, 5, 9)) == "cnn:2"
    assert _register(data, tmp_path, "big", (7, 7, 13)) == "big:1"
    assert [m.ref for m in list_models(data)] == ["big:1", "cnn:1", "cnn:2"]
    meta = json.loads((data / "models/cnn/2/meta.json").read_text())
    assert meta["grid"] == [5, 5, 9] and meta["dataset_sha256"] == "ab" * 32
    assert resolve_model(data, (5, 5, 9)) is None  # nothing active yet
    activate_model(data, "cnn:1")
    assert resolve_model(data, (5, 5, 9)) == data / "models/cnn/1/model.pt"
    assert resolve_model(data, (7, 7, 13)) is None
    assert resolve_model(data, (5, 5, 9), "cnn") == data / "models/cnn/2/model.pt"  # latest
    assert resolve_model(data, (7, 7, 13), "big:1") == data / "models/big/1/model.pt"
    assert get_model(data, "cnn:2").path.read_bytes() == b"weights"


@pytest.mark.parametrize("ref", ["cnn:9", "nope", "Bad Name", "cnn:x"])
def test_unknown_or_malformed_names_raise_naming_the_scene_field(tmp_path: Path, ref: str) -> None:
    _register(tmp_path, tmp_path, "cnn", (5, 5, 9))
    with pytest.raises(ModelNotFoundError, match="mechanics.model"):
        resolve_model(tmp_path, (5, 5, 9), ref)


def test_a_named_model_of_another_grid_is_refused(tmp_path: Path) -> None:
    _register(tmp_path, tmp_path, "cnn", (5, 5, 9))
    with pytest.raises(ModelNotFoundError, match="trained on grid 5x5x9"):
        resolve_model(tmp_path, (7, 7, 13), "cnn:1")


def test_the_registry_resolves_model_names_and_the_active_model(tmp_path: Path) -> None:
    from diathermy.errors import SceneError
    from diathermy.worker.registry import RegistryModels

    data = tmp_path / "data"
    shipped = tmp_path / "shipped.pt"

    def fallback(grid: tuple[int, int, int]) -> Path:
        return shipped

    models = RegistryModels(data, shipped=fallback)

    grid = (5, 5, 9)
    assert models(None, grid) == shipped  # empty registry: the shipped one
    _register(data, tmp_path, "cnn", grid)
    _register(data, tmp_path, "cnn", grid)
    assert models(None, grid) == shipped  # nothing active yet
    activate_model(data, "cnn:1")
    assert models(None, grid) == data / "models/cnn/1/model.pt"
    assert models("cnn", grid) == data / "models/cnn/2/model.pt"
    assert models("cnn:1", grid) == data / "models/cnn/1/model.pt"
    own = tmp_path / "own.pt"
    own.write_bytes(b"w")
    assert models(str(own), grid) == own  # a file path wins
    for bad in ["nope", "cnn:7", str(tmp_path / "missing.pt")]:
        with pytest.raises(SceneError, match=r"mechanics\.model.*neither a file"):
            models(bad, grid)
    with pytest.raises(SceneError, match=r"mechanics\.model"):
        models("cnn", (7, 7, 13))  # trained on another grid
