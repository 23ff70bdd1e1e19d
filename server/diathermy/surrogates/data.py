"""The mechanics dataset (HDF5, ``format="diathermy-dataset"`` v1) as torch datasets.

Splits are always by scenario: the steps of one scenario are strongly correlated, so a random
split of steps would leak the validation set into training.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import torch
from torch.utils.data import Dataset

from diathermy.errors import CheckpointError

DATASET_FORMAT = "diathermy-dataset"
DATASET_FORMAT_VERSION = 1
IN_MEMORY_LIMIT_BYTES = 1 << 30  # smaller selections are read once and kept in RAM

_ALIASES = {
    "index": ("index", "scenario"),
    "seed": ("seed",),
    "first": ("first", "first_sample", "start"),
    "count": ("count", "n_samples", "length"),
    "complete": ("complete",),
}


@dataclass(frozen=True)
class ScenarioRecord:
    """One scenario of the file: its samples are ``first .. first + count - 1``."""

    index: int
    seed: int
    first: int
    count: int
    complete: bool


@dataclass(frozen=True)
class DatasetInfo:
    """Header of a dataset file: grid (nz, ny, nx), spacing (dx, dy, dz) m, scenarios."""

    path: str
    grid_shape: tuple[int, int, int]
    spacing_m: tuple[float, float, float]
    n_samples: int
    scenarios: tuple[ScenarioRecord, ...]
    config: dict[str, Any] = field(default_factory=dict)
    material: dict[str, Any] = field(default_factory=dict)
    p0_pa: float = 101325.0

    def complete_scenarios(self) -> tuple[int, ...]:
        """Indices of the scenarios whose samples are all written."""
        return tuple(s.index for s in self.scenarios if s.complete and s.count > 0)

    def sample_indices(self, scenarios: tuple[int, ...] | list[int]) -> np.ndarray:
        """Sorted sample indices (int64) of the given scenarios."""
        by_index = {s.index: s for s in self.scenarios}
        try:
            parts = [
                np.arange(by_index[i].first, by_index[i].first + by_index[i].count)
                for i in scenarios
            ]
        except KeyError as err:
            raise CheckpointError(f"{self.path!r} has no scenario {err.args[0]}") from None
        return np.sort(np.concatenate(parts)) if parts else np.zeros(0, np.int64)


def _json_attr(attrs: h5py.AttributeManager, name: str) -> dict[str, Any]:
    raw = attrs.get(name)
    if raw is None:
        return {}
    try:
        value = json.loads(raw.decode() if isinstance(raw, bytes) else str(raw))
    except json.JSONDecodeError:
        return {}
    return value if isinstance(value, dict) else {}


def _field(table: Any, name: str, n: int) -> np.ndarray | None:
    names = table.dtype.names if isinstance(table, np.ndarray) else tuple(table.keys())
    for alias in _ALIASES[name]:
        if names is not None and alias in names:
            return np.asarray(table[alias]).reshape(n) if n else np.asarray(table[alias])
    return None


def _read_scenarios(f: h5py.File, n_samples: int) -> tuple[ScenarioRecord, ...]:
    """The /scenarios table, or (no table) the runs of /scenario below the commit marker."""
    if "scenarios" not in f:
        if "scenario" not in f:
            return (ScenarioRecord(0, 0, 0, n_samples, True),)
        scenario = np.asarray(f["scenario"][:n_samples], np.int64)
        ids, first, count = np.unique(scenario, return_index=True, return_counts=True)
        done = int(f.attrs.get("complete_scenarios", ids.max(initial=-1) + 1))
        return tuple(
            ScenarioRecord(int(i), 0, int(a), int(c), bool(i < done))
            for i, a, c in zip(ids, first, count, strict=True)
        )
    node = f["scenarios"]
    table: Any = node[...] if isinstance(node, h5py.Dataset) else {k: node[k][...] for k in node}
    n = len(table) if isinstance(table, np.ndarray) else len(next(iter(table.values()), []))
    cols = {name: _field(table, name, n) for name in _ALIASES}
    if cols["first"] is None or cols["count"] is None:
        raise CheckpointError("the /scenarios table lacks first-sample/count columns")
    index = cols["index"] if cols["index"] is not None else np.arange(n)
    seed = cols["seed"] if cols["seed"] is not None else np.zeros(n, np.int64)
    complete = cols["complete"] if cols["complete"] is not None else np.ones(n, bool)
    return tuple(
        ScenarioRecord(int(i), int(s), int(a), int(c), bool(done))
        for i, s, a, c, done in zip(
            index, seed, cols["first"], cols["count"], complete, strict=True
        )
    )


def read_dataset_info(path: str | os.PathLike[str]) -> DatasetInfo:
    """Open and validate a dataset file's header; :class:`CheckpointError` when it is not one."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"dataset file {str(path)!r} does not exist")
    try:
        with h5py.File(path, "r") as f:
            fmt = f.attrs.get("format")
            fmt = fmt.decode() if isinstance(fmt, bytes) else fmt
            if fmt != DATASET_FORMAT:
                raise CheckpointError(f"{str(path)!r} is not a diathermy dataset (format {fmt!r})")
            version = int(f.attrs.get("format_version", -1))
            if version != DATASET_FORMAT_VERSION:
                raise CheckpointError(
                    f"{str(path)!r} has dataset format version {version}; expected "
                    f"{DATASET_FORMAT_VERSION}"
                )
            for name in ("pressure", "level_set", "displacement"):
                if name not in f:
                    raise CheckpointError(f"{str(path)!r} has no /{name} dataset")
            n, *grid = f["pressure"].shape
            rows = int(f.attrs.get("complete_rows", n))  # rows past a commit marker are partial
            if (
                len(grid) != 3
                or f["level_set"].shape != f["pressure"].shape
                or f["displacement"].shape != (n, *grid, 3)
            ):
                raise CheckpointError(
                    f"{str(path)!r}: inconsistent shapes pressure {f['pressure'].shape}, "
                    f"level_set {f['level_set'].shape}, displacement {f['displacement'].shape}"
                )
            spacing = tuple(float(s) for s in f.attrs.get("spacing_m", (1.0, 1.0, 1.0)))
            config = _json_attr(f.attrs, "config")
            material = _json_attr(f.attrs, "material") or dict(config.get("material") or {})
            p0 = float(f.attrs.get("p0_pa", material.get("p_atm_pa", 101325.0)))
            return DatasetInfo(
                path=str(path),
                grid_shape=(int(grid[0]), int(grid[1]), int(grid[2])),
                spacing_m=spacing,  # type: ignore[arg-type]
                n_samples=min(rows, int(n)),
                scenarios=_read_scenarios(f, min(rows, int(n))),
                config=config,
                material=material,
                p0_pa=p0,
            )
    except OSError as err:
        raise CheckpointError(f"{str(path)!r} is not a readable HDF5 file ({err})") from None


def split_scenarios(
    scenarios: tuple[int, ...] | list[int], val_fraction: float, seed: int
) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Shuffle scenario indices with ``seed``; hold out ``ceil(val_fraction * n)`` (>= 1) of them."""
    ids = np.array(sorted(set(int(s) for s in scenarios)), np.int64)
    if not 0.0 < val_fraction < 1.0:
        raise CheckpointError(f"val fraction must lie in (0, 1), got {val_fraction}")
    if ids.size < 2:
        raise CheckpointError(
            f"need at least 2 complete scenarios to hold some out for validation, got {ids.size}"
        )
    order = np.random.default_rng(seed).permutation(ids)
    n_val = min(max(1, int(np.ceil(val_fraction * ids.size))), ids.size - 1)
    return tuple(sorted(order[n_val:].tolist())), tuple(sorted(order[:n_val].tolist()))


def chosen_split(
    scenarios: tuple[int, ...] | list[int], validation: tuple[int, ...] | list[int]
) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """(train, validation) with the validation scenarios named: all others train."""
    ids = sorted(set(int(s) for s in scenarios))
    val = sorted(set(int(s) for s in validation))
    unknown = sorted(set(val) - set(ids))
    if unknown:
        raise CheckpointError(f"validation scenarios {unknown} are not complete scenarios {ids}")
    train = [s for s in ids if s not in val]
    if not val or not train:
        raise CheckpointError(
            f"validation {val} must leave at least one of the scenarios {ids} for training"
        )
    return tuple(train), tuple(val)


def kfold_scenarios(
    scenarios: tuple[int, ...] | list[int], k: int, seed: int
) -> list[tuple[tuple[int, ...], tuple[int, ...]]]:
    """K folds by scenario: a list of (train, held out) pairs; every scenario is held out once."""
    ids = np.array(sorted(set(int(s) for s in scenarios)), np.int64)
    if k < 2 or k > ids.size:
        raise CheckpointError(f"folds must lie in [2, {ids.size}] (number of scenarios), got {k}")
    order = np.random.default_rng(seed).permutation(ids)
    folds = np.array_split(order, k)
    return [
        (tuple(sorted(np.setdiff1d(ids, held).tolist())), tuple(sorted(held.tolist())))
        for held in folds
    ]


def read_samples(
    path: str | os.PathLike[str], indices: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Samples as float32 arrays: pressure (S, nz, ny, nx) Pa, level set (S, ...) m, u (S, ..., 3) m."""
    idx = np.asarray(indices, np.int64)
    with h5py.File(path, "r") as f:
        out = []
        for name in ("pressure", "level_set", "displacement"):
            ds = f[name]
            out.append(
                np.stack([ds[int(i)] for i in idx]).astype(np.float32, copy=False)
                if idx.size
                else np.zeros((0, *ds.shape[1:]), np.float32)
            )
    return out[0], out[1], out[2]


class FieldDataset(Dataset):
    """Samples of a dataset file: item i -> (pressure (D, H, W) Pa, level set (D, H, W) m, u (3, D, H, W) m).

    Small selections are read once into memory; larger ones are read per item (the HDF5 handle is
    opened lazily in each DataLoader worker).
    """

    def __init__(self, path: str | os.PathLike[str], indices: np.ndarray) -> None:
        self.path = str(path)
        self.indices = np.asarray(indices, np.int64)
        self._file: h5py.File | None = None
        self._cache: tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None = None
        with h5py.File(self.path, "r") as f:
            per_sample = 6 * 4 * int(np.prod(f["pressure"].shape[1:]))
        if per_sample * self.indices.size <= IN_MEMORY_LIMIT_BYTES:
            p, phi, u = read_samples(self.path, self.indices)
            self._cache = (
                torch.from_numpy(p),
                torch.from_numpy(phi),
                torch.from_numpy(np.ascontiguousarray(np.moveaxis(u, -1, 1))),
            )

    def __len__(self) -> int:
        return int(self.indices.size)

    def __getitem__(self, item: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        if self._cache is not None:
            return self._cache[0][item], self._cache[1][item], self._cache[2][item]
        if self._file is None:
            self._file = h5py.File(self.path, "r")
        i = int(self.indices[item])
        u = np.asarray(self._file["displacement"][i], np.float32)
        return (
            torch.from_numpy(np.asarray(self._file["pressure"][i], np.float32)),
            torch.from_numpy(np.asarray(self._file["level_set"][i], np.float32)),
            torch.from_numpy(np.ascontiguousarray(np.moveaxis(u, -1, 0))),
        )

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_file"] = None  # h5py handles do not cross process boundaries
        return state
