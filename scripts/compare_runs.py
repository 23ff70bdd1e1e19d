"""Compare two run files bit for bit: every dataset, the attributes, and each step report except
its wall times (``wall_s`` of the step and of every effect, and the solver timings in seconds of
an effect's ``extra``: every key there ending in ``_s``, e.g. ``operator_s``, ``solve_s``).

    python scripts/compare_runs.py BASELINE.h5 CANDIDATE.h5

Prints one line per difference and a summary; exits 0 when the files agree, 1 otherwise.
"""

from __future__ import annotations

import json
import sys
from typing import Any

import h5py
import numpy as np


def _without_wall(obj: Any, *, timings: bool = False) -> Any:
    """The report with every ``wall_s`` key (and the ``*_s`` timings of ``extra``) dropped."""
    if isinstance(obj, dict):
        return {
            k: _without_wall(v, timings=k == "extra")
            for k, v in obj.items()
            if k != "wall_s" and not (timings and k.endswith("_s"))
        }
    if isinstance(obj, list):
        return [_without_wall(v) for v in obj]
    return obj


def _datasets(f: h5py.File) -> dict[str, h5py.Dataset]:
    out: dict[str, h5py.Dataset] = {}
    f.visititems(lambda n, o: out.__setitem__(n, o) if isinstance(o, h5py.Dataset) else None)
    return out


def compare(a_path: str, b_path: str) -> list[str]:
    """Differences between two run files (empty when identical up to wall times)."""
    diffs: list[str] = []
    with h5py.File(a_path, "r") as a, h5py.File(b_path, "r") as b:
        for key in sorted(set(a.attrs) | set(b.attrs)):
            if key == "diathermy_version":
                continue
            va, vb = a.attrs.get(key), b.attrs.get(key)
            if not np.array_equal(np.asarray(va), np.asarray(vb)):
                diffs.append(f"attr {key}: differs")
        da, db = _datasets(a), _datasets(b)
        for name in sorted(set(da) ^ set(db)):
            diffs.append(f"dataset {name}: only in {'baseline' if name in da else 'candidate'}")
        for name in sorted(set(da) & set(db)):
            if name == "reports":
                ra = [_without_wall(json.loads(r)) for r in da[name].asstr()[:]]
                rb = [_without_wall(json.loads(r)) for r in db[name].asstr()[:]]
                if len(ra) != len(rb):
                    diffs.append(f"reports: {len(ra)} vs {len(rb)} records")
                for i, (x, y) in enumerate(zip(ra, rb, strict=False)):
                    if x != y:
                        diffs.append(f"reports[{i}] (step {x.get('step')}): differ")
                continue
            x, y = da[name], db[name]
            if x.shape != y.shape or x.dtype != y.dtype:
                diffs.append(f"{name}: {x.shape} {x.dtype} vs {y.shape} {y.dtype}")
                continue
            n_bad = 0
            for i in range(x.shape[0]) if x.ndim > 1 else [slice(None)]:
                xa, ya = x[i], y[i]
                # bitwise: NaN == NaN at the same place, -0.0 != +0.0
                if xa.tobytes() != ya.tobytes():
                    n_bad += 1
            if n_bad:
                diffs.append(f"{name}: {n_bad} records differ")
    return diffs


def main() -> None:
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    diffs = compare(sys.argv[1], sys.argv[2])
    for d in diffs:
        print(d)
    ok = "IDENTICAL (every dataset bitwise, reports without wall times)"
    print(ok if not diffs else f"{len(diffs)} differences")
    sys.exit(1 if diffs else 0)


if __name__ == "__main__":
    main()
