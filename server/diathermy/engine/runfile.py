"""The HDF5 run file: one record per written step, appended as the simulation advances.

Layout (stable; later effects add names, never change the layout):
    /time                 (n,)                  simulated time in s
    /step                 (n,)                  step index
    /fields/<name>        (n, nz, ny, nx)       nodal scalars: potential, temperature, pressure, ...
                          (n, nz, ny, nx, 3)    nodal vectors: displacement (x, y, z components)
    /cell_fields/<name>   (n, n_tets)           per-tetrahedron values: joule_heat, strain_energy,
                                                removed (1 where the tissue is cut away)
    /reports              (n,)                  one JSON step report per record (UTF-8 strings)
Root attributes: format, format_version, diathermy_version, scene (JSON), grid_shape (nz, ny, nx),
spacing_m (dx, dy, dz) on a uniform grid or the node coordinates node_x_m (nx,), node_y_m (ny,),
node_z_m (nz,) on a graded one, origin_m (x0, y0, z0), block_m (Lx, Ly, Lz)
(``mesh.grid_from_attrs`` reads the grid back).
"""

from __future__ import annotations

import json
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np

from diathermy.errors import CheckpointError
from diathermy.mesh import Grid
from diathermy.mesh.grid_attrs import grid_attrs
from diathermy.version import __version__

RUN_FORMAT = "diathermy-run"
RUN_FORMAT_VERSION = 1
_STR = h5py.string_dtype(encoding="utf-8")


class RunWriter:
    """Appends step records to a run file; use as a context manager."""

    def __init__(self, path: str | Path, grid: Grid, scene_json: str) -> None:
        self.path = Path(path)
        self.grid = grid
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._f = h5py.File(self.path, "w")
        except OSError as err:
            raise CheckpointError(f"cannot create run file {self.path}: {err}") from None
        f = self._f
        f.attrs.update(
            format=RUN_FORMAT,
            format_version=RUN_FORMAT_VERSION,
            diathermy_version=__version__,
            scene=scene_json,
            **grid_attrs(grid),
        )
        f.create_dataset("time", shape=(0,), maxshape=(None,), dtype="f8", chunks=(1024,))
        f.create_dataset("step", shape=(0,), maxshape=(None,), dtype="i8", chunks=(1024,))
        f.create_dataset("reports", shape=(0,), maxshape=(None,), dtype=_STR, chunks=(256,))
        f.create_group("fields")
        f.create_group("cell_fields")
        self.n = 0

    def _append(self, group: h5py.Group, name: str, value: np.ndarray) -> None:
        value = np.asarray(value, dtype=np.float32 if value.dtype == np.float16 else value.dtype)
        if name not in group:
            group.create_dataset(
                name,
                shape=(0, *value.shape),
                maxshape=(None, *value.shape),
                dtype=value.dtype,
                chunks=(1, *value.shape),
                compression="gzip",
                compression_opts=1,
                shuffle=True,
            )
        ds = group[name]
        if ds.shape[1:] != value.shape:
            raise CheckpointError(f"run file field {name}: shape {value.shape} != {ds.shape[1:]}")
        if ds.shape[0] < self.n:  # a field that appeared late: earlier records are NaN
            ds.resize(self.n, axis=0)
            ds[: self.n] = np.nan
        ds.resize(self.n + 1, axis=0)
        ds[self.n] = value

    def append(
        self,
        *,
        time_s: float,
        step: int,
        fields: dict[str, np.ndarray],
        cell_fields: dict[str, np.ndarray],
        report: dict[str, Any],
    ) -> None:
        """Write one record: nodal fields grid-shaped, cell fields (n_tets,), the step report."""
        f = self._f
        for name, arr in fields.items():
            self._append(f["fields"], name, arr)
        for name, arr in cell_fields.items():
            self._append(f["cell_fields"], name, arr)
        for name, value in (("time", time_s), ("step", step)):
            f[name].resize(self.n + 1, axis=0)
            f[name][self.n] = value
        f["reports"].resize(self.n + 1, axis=0)
        f["reports"][self.n] = json.dumps(report)
        self.n += 1
        f.flush()

    def close(self) -> None:
        self._f.close()

    def __enter__(self) -> RunWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def read_run(path: str | Path) -> dict[str, Any]:
    """Load a whole run file into memory (small runs, tests): time, fields, cell_fields, reports."""
    try:
        f = h5py.File(path, "r")
    except OSError as err:
        raise CheckpointError(f"{path} is not a readable HDF5 run file: {err}") from None
    with f:
        if f.attrs.get("format") != RUN_FORMAT:
            raise CheckpointError(f"{path} is not a diathermy run file")
        return {
            "attrs": dict(f.attrs),
            "time": f["time"][:],
            "step": f["step"][:],
            "fields": {k: v[:] for k, v in f["fields"].items()},
            "cell_fields": {k: v[:] for k, v in f["cell_fields"].items()},
            "reports": [json.loads(r) for r in f["reports"].asstr()[:]],
        }
