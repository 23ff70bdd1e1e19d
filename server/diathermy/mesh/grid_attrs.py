"""A grid as flat attributes of a file or message, and back (run files, checkpoints).

A uniform grid keeps the attributes it always had: ``grid_shape`` (nz, ny, nx), ``spacing_m``
(dx, dy, dz), ``origin_m``, ``block_m``. A graded grid has no single spacing: it carries its node
coordinates per axis instead, ``node_x_m`` (nx,), ``node_y_m`` (ny,), ``node_z_m`` (nz,), in m.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from diathermy.errors import MeshError
from diathermy.mesh.grid import Grid

AXIS_KEYS = ("node_x_m", "node_y_m", "node_z_m")


def grid_attrs(grid: Grid) -> dict[str, np.ndarray]:
    """The attributes that describe ``grid`` (see the module docstring)."""
    out = {"grid_shape": np.asarray(grid.shape)}
    if grid.is_uniform:
        out["spacing_m"] = np.asarray(grid.spacing_m)
    else:
        out.update({k: np.asarray(a) for k, a in zip(AXIS_KEYS, grid.axes(), strict=True)})
    out["origin_m"] = np.asarray(grid.origin_m)
    out["block_m"] = np.asarray(grid.size_m)
    return out


def grid_from_attrs(attrs: Mapping[str, Any]) -> Grid:
    """The grid the attributes describe; raises MeshError when they are missing or inconsistent."""
    try:
        if all(k in attrs for k in AXIS_KEYS):
            return Grid.from_axes(*(np.asarray(attrs[k], dtype=float) for k in AXIS_KEYS))
        shape = tuple(int(n) for n in np.asarray(attrs["grid_shape"]))
        size = tuple(float(s) for s in np.asarray(attrs["block_m"]))
        origin = tuple(float(o) for o in np.asarray(attrs.get("origin_m", (0.0, 0.0, 0.0))))
    except KeyError as err:
        raise MeshError(f"grid attributes lack {err.args[0]!r}") from None
    return Grid(shape, size_m=size, origin_m=origin)  # type: ignore[arg-type]
