"""The run file keeps its documented layout, appends step by step, and rejects foreign files."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from diathermy.engine.runfile import RunWriter, read_run
from diathermy.errors import CheckpointError
from diathermy.mesh import Grid


def test_layout_and_late_fields(tmp_path):
    grid = Grid((3, 4, 5))
    path = tmp_path / "r.h5"
    with RunWriter(path, grid, '{"name": "t"}') as w:
        for n in range(3):
            fields = {"temperature": np.full(grid.shape, 300.0 + n)}
            if n >= 1:
                fields["displacement"] = np.full((*grid.shape, 3), 1e-3 * n)
            w.append(
                time_s=0.03 * (n + 1),
                step=n + 1,
                fields=fields,
                cell_fields={"joule_heat": np.arange(7.0)},
                report={"step": n + 1},
            )
    run = read_run(path)
    assert run["fields"]["temperature"].shape == (3, 3, 4, 5)
    assert run["fields"]["displacement"].shape == (3, 3, 4, 5, 3)
    assert np.isnan(run["fields"]["displacement"][0]).all()
    assert run["fields"]["displacement"][2, 0, 0, 0, 2] == pytest.approx(2e-3)
    assert np.allclose(run["time"], [0.03, 0.06, 0.09])
    assert [r["step"] for r in run["reports"]] == [1, 2, 3]
    assert tuple(run["attrs"]["grid_shape"]) == (3, 4, 5)
    assert np.allclose(run["attrs"]["spacing_m"], grid.spacing_m)


def test_foreign_and_corrupt_files(tmp_path):
    foreign = tmp_path / "f.h5"
    with h5py.File(foreign, "w") as f:
        f["x"] = 1
    with pytest.raises(CheckpointError, match="not a diathermy run file"):
        read_run(foreign)
    junk = tmp_path / "j.h5"
    junk.write_bytes(b"not hdf5 at all")
    with pytest.raises(CheckpointError, match="not a readable HDF5"):
        read_run(junk)
