"""Measure what a change of the dataset generator's physics changed: generate one small dataset
with each of two source trees and compare them sample by sample.

    python scripts/datagen_change.py OLD_SERVER_DIR NEW_SERVER_DIR [--grid NZ NY NX]
        [--scenarios N] [--steps N] [--out DIR]

Both trees run the same config (a weak, fast-cutting tissue so the cut grows within the run);
prints, per field, how many samples differ and the largest relative difference, and how many
tets the healthy rule of each dataset calls removed at the end of each scenario.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np

GEN = """
import sys
from diathermy.datagen import DatagenConfig, generate
generate(DatagenConfig.model_validate_json(sys.argv[1]), sys.argv[2], workers=1)
"""


def config(grid: list[int], scenarios: int, steps: int) -> dict:
    return {
        "grid": grid,
        "n_scenarios": scenarios,
        "n_steps": steps,
        "seed": 3,
        "dtype": "float64",
        "p_min_pa": 4e5,
        "p_max_pa": 1e6,
        "mechanics_rtol": 1e-10,
        "material": {"damage_kappa_j_per_m3": 2e3},
        "level_set": {"v0_m_per_s": 0.05},
    }


def run(server: str, cfg: dict, out: Path) -> None:
    env = {**os.environ, "PYTHONPATH": server}
    subprocess.run([sys.executable, "-c", GEN, json.dumps(cfg), str(out)], env=env, check=True)


def removed_count(phi: np.ndarray, server: str, cfg: dict) -> int:
    """Tets the generator of ``server`` calls not healthy under phi."""
    code = (
        "import sys, json, numpy as np\n"
        "from diathermy.datagen import DatagenConfig\n"
        "from diathermy.datagen.physics import fem_physics\n"
        "p = fem_physics(DatagenConfig.model_validate_json(sys.argv[1]))\n"
        "print(int((~p.healthy_tets(np.load(sys.argv[2]))).sum()))\n"
    )
    tmp = Path("/tmp/_phi.npy")
    np.save(tmp, phi)
    env = {**os.environ, "PYTHONPATH": server}
    res = subprocess.run(
        [sys.executable, "-c", code, json.dumps(cfg), str(tmp)],
        env=env, check=True, capture_output=True, text=True,
    )  # fmt: skip
    return int(res.stdout.strip())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("old")
    ap.add_argument("new")
    ap.add_argument("--grid", type=int, nargs=3, default=[9, 9, 17])
    ap.add_argument("--scenarios", type=int, default=4)
    ap.add_argument("--steps", type=int, default=16)
    ap.add_argument("--out", type=Path, default=Path("/tmp/datagen_change"))
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    cfg = config(a.grid, a.scenarios, a.steps)
    paths = {}
    for label, server in (("old", a.old), ("new", a.new)):
        paths[label] = a.out / f"{label}.h5"
        paths[label].unlink(missing_ok=True)
        run(server, cfg, paths[label])
    print(f"config: grid {a.grid}, {a.scenarios} scenarios x {a.steps} steps, seed 3")
    with h5py.File(paths["old"], "r") as fo, h5py.File(paths["new"], "r") as fn:
        names = sorted(k for k in fo if isinstance(fo[k], h5py.Dataset))
        for name in names:
            x, y = fo[name][()], fn[name][()]
            if x.shape != y.shape:
                print(f"{name}: shape {x.shape} vs {y.shape}")
                continue
            rows = x.reshape(x.shape[0], -1) if x.ndim else x.reshape(1, 1)
            rows_n = y.reshape(rows.shape)
            differ = int(np.count_nonzero(np.any(rows != rows_n, axis=1)))
            rel = ""
            if np.issubdtype(x.dtype, np.floating) and differ:
                scale = np.abs(x).max() or 1.0
                rel = f", max |diff| / max |old| = {np.abs(x - y).max() / scale:.3g}"
            print(f"{name}: {differ} of {rows.shape[0]} rows differ{rel}")
        phi_o, phi_n = fo["level_set"][()], fn["level_set"][()]
        steps = fo["step"][()] if "step" in fo else None
        last = [i for i in range(len(phi_o)) if steps is None or steps[i] == a.steps - 1]
        for i in last:
            flat_o, flat_n = phi_o[i].ravel(), phi_n[i].ravel()
            print(
                f"row {i} (last step of a scenario): removed tets old rule/old phi "
                f"{removed_count(flat_o, a.old, cfg)}, new rule/new phi "
                f"{removed_count(flat_n, a.new, cfg)}, new rule/old phi "
                f"{removed_count(flat_o, a.new, cfg)}"
            )


if __name__ == "__main__":
    main()
