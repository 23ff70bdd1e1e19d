"""Writes small synthetic files in the dataset format (``diathermy-dataset`` v1) for tests.

The displacement is a smooth local function of the pressure (the gradient of a Gaussian-smoothed
overpressure, masked by the level set): physically shaped, cheap, and learnable by a small CNN.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
from scipy.ndimage import gaussian_filter

P0 = 101325.0


def synthetic_sample(
    rng: np.random.Generator, grid: tuple[int, int, int], spacing: tuple[float, float, float]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One (pressure Pa, level set m, displacement m (..., 3)) sample on a (nz, ny, nx) grid."""
    nz, ny, nx = grid
    dx, dy, dz = spacing
    z, y, x = np.meshgrid(np.arange(nz) * dz, np.arange(ny) * dy, np.arange(nx) * dx, indexing="ij")
    p = np.full(grid, P0)
    for _ in range(int(rng.integers(1, 4))):
        cx, cy = rng.uniform(0, nx * dx), rng.uniform(0, ny * dy)
        r2 = (x - cx) ** 2 + (y - cy) ** 2 + (z - (nz - 1) * dz) ** 2
        p += rng.uniform(2e3, 2e4) * np.exp(-r2 / (2 * (2 * dx) ** 2))
    phi = (
        (nz - 1) * dz
        - z
        - rng.uniform(0, 1.5 * dz) * np.exp(-((x - 0.5 * nx * dx) ** 2) / (4 * dx * dx))
    )
    smooth = gaussian_filter(p - P0, sigma=1.0, mode="nearest")
    gz, gy, gx = np.gradient(smooth, dz, dy, dx)
    u = -1e-9 * np.stack([gx, gy, gz], axis=-1) * (phi > 0)[..., None]
    return p.astype(np.float32), phi.astype(np.float32), u.astype(np.float32)


def write_synthetic_dataset(
    path: Path,
    *,
    grid: tuple[int, int, int] = (9, 9, 17),
    n_scenarios: int = 6,
    n_steps: int = 4,
    seed: int = 0,
    incomplete_last: bool = False,
) -> Path:
    """A dataset file with ``n_scenarios`` x ``n_steps`` samples (the last scenario optionally
    marked incomplete, as a crashed generator would leave it)."""
    nz, ny, nx = grid
    spacing = (0.2 / (nx - 1), 0.1 / (ny - 1), 0.1 / (nz - 1))
    n = n_scenarios * n_steps
    rng = np.random.default_rng(seed)
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "diathermy-dataset"
        f.attrs["format_version"] = 1
        f.attrs["diathermy_version"] = "test"
        config = {"p_min_pa": 101325.0, "p_max_pa": 121325.0, "n_scenarios": n_scenarios,
                  "n_steps": n_steps, "seed": seed, "grid": list(grid), "block": [0.2, 0.1, 0.1]}  # fmt: skip
        f.attrs["config"] = json.dumps(config)
        f.attrs["grid_shape"] = np.array(grid, np.int64)
        f.attrs["spacing_m"] = np.array(spacing)
        f.attrs["origin_m"] = np.zeros(3)
        f.attrs["block_m"] = np.array([0.2, 0.1, 0.1])
        f.attrs["material"] = json.dumps({"youngs_modulus_pa": 0.27e6, "poisson_ratio": 0.4})
        kw = {"dtype": np.float32, "compression": "gzip", "compression_opts": 1, "shuffle": True}
        ds_p = f.create_dataset("pressure", (n, *grid), chunks=(1, *grid), **kw)
        ds_phi = f.create_dataset("level_set", (n, *grid), chunks=(1, *grid), **kw)
        ds_u = f.create_dataset("displacement", (n, *grid, 3), chunks=(1, *grid, 3), **kw)
        for s in range(n):
            ds_p[s], ds_phi[s], ds_u[s] = synthetic_sample(rng, grid, spacing)
        f["scenario"] = np.repeat(np.arange(n_scenarios), n_steps).astype(np.int32)
        f["step"] = np.tile(np.arange(n_steps), n_scenarios).astype(np.int32)
        table = np.zeros(
            n_scenarios,
            dtype=[
                ("index", "i4"),
                ("seed", "i8"),
                ("first", "i8"),
                ("count", "i4"),
                ("complete", "?"),
            ],
        )
        table["index"] = np.arange(n_scenarios)
        table["seed"] = seed + np.arange(n_scenarios)
        table["first"] = np.arange(n_scenarios) * n_steps
        table["count"] = n_steps
        table["complete"] = True
        if incomplete_last:
            table["complete"][-1] = False
        f["scenarios"] = table
    return path
