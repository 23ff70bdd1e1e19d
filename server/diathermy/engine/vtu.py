"""ParaView output: the tetrahedral mesh with nodal and cell fields as VTU, and a .pvd series."""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

import meshio
import numpy as np


def write_vtu(
    path: str | Path,
    points: np.ndarray,
    tets: np.ndarray,
    point_data: dict[str, np.ndarray],
    cell_data: dict[str, np.ndarray],
) -> Path:
    """Write one VTU file: points (n, 3) m, tets (m, 4), nodal (n[, 3]) and per-tet (m,) arrays."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh = meshio.Mesh(
        points,
        [("tetra", tets.astype(np.int64))],
        point_data={k: np.asarray(v, dtype=np.float64) for k, v in point_data.items()},
        cell_data={k: [np.asarray(v, dtype=np.float64)] for k, v in cell_data.items()},
    )
    meshio.write(path, mesh, file_format="vtu", binary=True)
    return path


def write_pvd(path: str | Path, entries: list[tuple[float, str]]) -> Path:
    """A ParaView collection listing (time in s, VTU file name relative to the .pvd) pairs."""
    path = Path(path)
    lines = [
        '<?xml version="1.0"?>',
        '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
        "  <Collection>",
        *(f'    <DataSet timestep="{t!r}" group="" part="0" file={quoteattr(f)}/>' for t, f in entries),
        "  </Collection>",
        "</VTKFile>",
    ]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
