"""The model registry on disk: ``DATA_DIR/models/<name>/<version>/{model.pt, meta.json}``.

Versions are whole numbers allocated by an exclusive ``mkdir`` (two trainers finishing at once
get different versions). ``models/active.json`` maps a grid ``NZxNYxNX`` to the ``name:version``
sessions on that grid use. Torch-free: metadata lives in ``meta.json``, not in the checkpoint.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from diathermy.errors import SceneError

MODELS_DIR = "models"
ACTIVE_FILE = "active.json"
MODEL_FILE = "model.pt"
META_FILE = "meta.json"
_NAME = re.compile(r"^[a-z0-9][a-z0-9_-]{0,63}$")


class ModelNotFoundError(SceneError, LookupError):
    """No model by that name (and version) in the registry, or not for this grid."""


@dataclass(frozen=True)
class ModelInfo:
    """A registered model: where it is, what it was trained on and how good it is."""

    name: str
    version: int
    grid: tuple[int, int, int]
    architecture: dict[str, Any]
    dataset_sha256: str
    dataset: dict[str, Any]
    metrics: dict[str, Any]
    training: dict[str, Any]
    created_at: float
    job_id: str | None = None
    owner: str | None = None
    path: Path = field(default=Path(), compare=False)

    @property
    def ref(self) -> str:
        return f"{self.name}:{self.version}"

    def to_json(self) -> dict[str, Any]:
        data = asdict(self)
        data.pop("path")
        data["grid"] = list(self.grid)
        return data


def grid_key(grid_shape: tuple[int, int, int] | list[int]) -> str:
    return "x".join(str(int(n)) for n in grid_shape)


def models_dir(data_dir: str | Path) -> Path:
    return Path(data_dir) / MODELS_DIR


def parse_ref(ref: str) -> tuple[str, int | None]:
    """``name`` or ``name:version`` -> (name, version or None); ``ModelNotFoundError`` if malformed."""
    name, sep, version = ref.partition(":")
    if not _NAME.match(name) or (sep and not version.isdigit()):
        raise ModelNotFoundError(f"mechanics.model: {ref!r} is not a model name or name:version")
    return name, int(version) if sep else None


def _write_json(path: Path, data: Any) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def _read_meta(folder: Path) -> ModelInfo | None:
    try:
        data = json.loads((folder / META_FILE).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return None  # a version still being written, or not a model folder
    data["grid"] = tuple(data["grid"])
    return ModelInfo(**data, path=folder / MODEL_FILE)


def register_model(
    data_dir: str | Path,
    checkpoint: str | Path,
    *,
    name: str,
    grid: tuple[int, int, int],
    architecture: dict[str, Any],
    dataset_sha256: str,
    dataset: dict[str, Any],
    metrics: dict[str, Any],
    training: dict[str, Any],
    job_id: str | None = None,
    owner: str | None = None,
) -> ModelInfo:
    """Copy ``checkpoint`` into the registry as the next version of ``name``; returns its info."""
    parse_ref(name)
    base = models_dir(data_dir) / name
    base.mkdir(parents=True, exist_ok=True)
    while True:
        version = 1 + max((int(p.name) for p in base.iterdir() if p.name.isdigit()), default=0)
        folder = base / str(version)
        try:
            folder.mkdir()
            break
        except FileExistsError:
            continue
    shutil.copyfile(checkpoint, folder / MODEL_FILE)
    info = ModelInfo(
        name=name,
        version=version,
        grid=(int(grid[0]), int(grid[1]), int(grid[2])),
        architecture=architecture,
        dataset_sha256=dataset_sha256,
        dataset=dataset,
        metrics=metrics,
        training=training,
        created_at=time.time(),
        job_id=job_id,
        owner=owner,
        path=folder / MODEL_FILE,
    )
    _write_json(folder / META_FILE, info.to_json())  # last: a version is visible once whole
    return info


def list_models(data_dir: str | Path) -> list[ModelInfo]:
    """Every registered model, by name then version."""
    root = models_dir(data_dir)
    if not root.is_dir():
        return []
    found = []
    for name_dir in sorted(p for p in root.iterdir() if p.is_dir()):
        for version_dir in sorted(
            (p for p in name_dir.iterdir() if p.name.isdigit()), key=lambda p: int(p.name)
        ):
            info = _read_meta(version_dir)
            if info is not None:
                found.append(info)
    return found


def get_model(data_dir: str | Path, ref: str) -> ModelInfo:
    """A model by ``name:version`` (or ``name``: its latest version)."""
    name, version = parse_ref(ref)
    versions = [m for m in list_models(data_dir) if m.name == name]
    if version is not None:
        versions = [m for m in versions if m.version == version]
    if not versions:
        raise ModelNotFoundError(f"mechanics.model: no model {ref!r} in the registry")
    return versions[-1]


def active_models(data_dir: str | Path) -> dict[str, str]:
    """Grid key ``NZxNYxNX`` -> active ``name:version``."""
    path = models_dir(data_dir) / ACTIVE_FILE
    try:
        return dict(json.loads(path.read_text(encoding="utf-8")))
    except (OSError, json.JSONDecodeError):
        return {}


def activate_model(data_dir: str | Path, ref: str) -> ModelInfo:
    """Make ``ref`` the model sessions on its grid use; returns it."""
    info = get_model(data_dir, ref)
    active = active_models(data_dir)
    active[grid_key(info.grid)] = info.ref
    _write_json(models_dir(data_dir) / ACTIVE_FILE, active)
    return info


def resolve_model(
    data_dir: str | Path, grid_shape: tuple[int, int, int], name: str | None = None
) -> Path | None:
    """The checkpoint a session on ``grid_shape`` uses: ``name`` (``name[:version]``) if given,
    else the grid's active model; None when no name is given and none is active.

    A named model that does not exist, or was trained on another grid, raises
    ``ModelNotFoundError`` (a ``SceneError`` naming ``mechanics.model``).
    """
    if name is None:
        ref = active_models(data_dir).get(grid_key(grid_shape))
        if ref is None:
            return None
        try:
            return get_model(data_dir, ref).path
        except ModelNotFoundError:
            return None  # the active version was deleted by hand
    info = get_model(data_dir, name)
    if tuple(info.grid) != tuple(int(n) for n in grid_shape):
        raise ModelNotFoundError(
            f"mechanics.model: {info.ref} was trained on grid {grid_key(info.grid)}, "
            f"the scene's grid is {grid_key(grid_shape)}"
        )
    return info.path


class RegistryModels:
    """The ``ModelResolver`` of a data directory's registry: ``mechanics.model`` as a file
    path, else a registry name (``name`` or ``name:version``); with none given, the grid's
    active model, else the model shipped for the grid. Errors name ``mechanics.model``."""

    def __init__(
        self,
        data_dir: str | Path,
        shipped: Callable[[tuple[int, int, int]], Path] | None = None,
    ) -> None:
        self.data_dir = Path(data_dir)
        self.shipped = shipped

    def _shipped(self, grid: tuple[int, int, int]) -> Path:
        if self.shipped is not None:
            return self.shipped(grid)
        from diathermy.engine.backends import shipped_models

        return shipped_models(None, grid)

    def __call__(self, model: str | None, grid: tuple[int, int, int]) -> Path:
        if model is not None and Path(model).is_file():
            return Path(model)
        if model is None:
            active = resolve_model(self.data_dir, grid)
            return active if active is not None else self._shipped(grid)
        try:
            path = resolve_model(self.data_dir, grid, model)
        except SceneError as err:
            raise SceneError(
                f"mechanics.model: {model!r} is neither a file nor a model in the registry at "
                f"{self.data_dir} ({err})"
            ) from None
        if path is None or not Path(path).is_file():
            raise SceneError(f"mechanics.model: registry model {model!r} has no checkpoint file")
        return Path(path)
