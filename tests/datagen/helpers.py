"""Read a whole small dataset file for comparisons."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import h5py
import numpy as np


def file_contents(path: Path) -> dict[str, Any]:
    """Every dataset (committed rows only) and every root attribute."""
    with h5py.File(path, "r") as f:
        rows = int(f.attrs["complete_rows"])
        out: dict[str, Any] = {f"attr:{k}": v for k, v in f.attrs.items()}
        for name, ds in f.items():
            out[name] = ds[:rows]
            out[f"len:{name}"] = ds.shape[0]
    return out


def assert_same_contents(a: Path, b: Path) -> None:
    ca, cb = file_contents(a), file_contents(b)
    assert ca.keys() == cb.keys()
    for key in ca:
        va, vb = ca[key], cb[key]
        if isinstance(va, np.ndarray):
            assert va.dtype == vb.dtype and va.shape == vb.shape, key
            assert va.tobytes() == vb.tobytes(), key  # bit-identical
        else:
            assert va == vb, key
