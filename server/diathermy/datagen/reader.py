"""Streaming reader of an Algorithm 1 dataset: complete scenarios only, one sample at a time."""

from __future__ import annotations

import json
import os
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np

from diathermy.datagen.storage import FIELDS, check_layout
from diathermy.errors import CheckpointError


class DatasetReader:
    """Random access to the committed samples of a dataset file, without loading it.

    The file opens lazily and reopens in a forked process (DataLoader workers), so one reader
    can be handed to several processes. Only rows below the commit marker are visible.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._f: h5py.File | None = None
        self._pid = -1
        f = self._file()
        self.n_rows = int(f.attrs["complete_rows"])
        self.n_complete_scenarios = int(f.attrs["complete_scenarios"])
        self.attrs: dict[str, Any] = dict(f.attrs)
        self.config: dict[str, Any] = json.loads(f.attrs["config"])
        self.grid_shape = tuple(int(n) for n in f.attrs["grid_shape"])
        self._scenario = f["scenario"][: self.n_rows]
        self._step = f["step"][: self.n_rows]

    def _file(self) -> h5py.File:
        if self._f is None or self._pid != os.getpid():
            try:
                self._f = h5py.File(self.path, "r")
            except OSError as err:
                raise CheckpointError(f"{self.path} is not a readable HDF5 file: {err}") from None
            self._pid = os.getpid()
            check_layout(self._f, self.path)
        return self._f

    def __len__(self) -> int:
        return self.n_rows

    @property
    def step_of_row(self) -> np.ndarray:
        """Step index (n_rows,) of each committed row."""
        return self._step

    def scenario_ids(self) -> np.ndarray:
        """Sorted indices of the complete scenarios."""
        return np.unique(self._scenario)

    def rows_of(self, scenario: int) -> np.ndarray:
        """Row indices of one scenario, in step order."""
        return np.flatnonzero(self._scenario == scenario)

    def sample(self, i: int) -> dict[str, np.ndarray]:
        """Row i: pressure (nz, ny, nx) Pa, level_set (nz, ny, nx) m, displacement (..., 3) m."""
        if not -self.n_rows <= i < self.n_rows:
            raise IndexError(f"sample {i} out of range for {self.n_rows} committed samples")
        i %= self.n_rows
        f = self._file()
        return {name: f[name][i] for name in FIELDS}

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None

    def __enter__(self) -> DatasetReader:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_f"], state["_pid"] = None, -1  # h5py handles do not pickle
        return state
