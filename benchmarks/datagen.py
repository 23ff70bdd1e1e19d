"""Dataset generation (Algorithm 1) throughput: 1 vs 2 local workers vs Dask, and the paper's cost.

    python benchmarks/datagen.py [--grids 17x17x33 33x33x65] [--scenarios 4] [--steps 3]
                                 [--repeat 1] [--large]

For each grid: samples per second with 1 and 2 local worker processes and with the Dask engine on
a 2-worker local cluster (ratios against 1 local worker), the median time of one FEM mechanics
solve + level-set step per sample, and the compressed bytes per sample. Then it projects the
paper's dataset (200,000 samples at 64x64x128) in core-hours and disk, from a measured sample at
64x64x128 with --large, else extrapolated from the two largest grids by a power law in the node
count. Writes benchmarks/results/datagen.md. The machine is shared: read the ratios.
"""

from __future__ import annotations

import argparse
import math
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

import h5py
from threadpoolctl import threadpool_limits

from diathermy.datagen import DatagenConfig, generate, run_scenario
from diathermy.datagen.physics import fem_physics
from diathermy.scene import parse_grid

PAPER_SAMPLES = 200_000
PAPER_GRID = (64, 64, 128)
RESULTS = Path(__file__).parent / "results" / "datagen.md"


def bytes_per_sample(path: Path) -> float:
    """Stored (compressed) bytes of the sample fields per sample."""
    with h5py.File(path, "r") as f:
        n = int(f.attrs["complete_rows"])
        total = sum(
            f[name].id.get_storage_size() for name in ("pressure", "level_set", "displacement")
        )
    return total / n


def time_per_sample(config: DatagenConfig) -> float:
    """Median wall time of one sample (walk + solve + level set) in one process, s."""
    times = []
    with threadpool_limits(limits=1):  # as the engines run it
        physics = fem_physics(config)
        t = time.perf_counter()
        for _ in run_scenario(config, 0, physics):
            now = time.perf_counter()
            times.append(now - t)
            t = now
    return statistics.median(times[1:] if len(times) > 1 else times)


def run_engine(config: DatagenConfig, engine: str, workers: int, repeat: int) -> float:
    """Median samples per second of a whole ``generate`` call."""
    rates = []
    for _ in range(repeat):
        with tempfile.TemporaryDirectory() as tmp:
            s = generate(config, Path(tmp) / "d.h5", engine=engine, workers=workers)  # type: ignore[arg-type]
            rates.append(s.samples / s.wall_s)
    return statistics.median(rates)


def measure(grid: tuple[int, int, int], scenarios: int, steps: int, repeat: int) -> dict:
    config = DatagenConfig(grid=grid, n_scenarios=scenarios, n_steps=steps, seed=1)
    row: dict = {"grid": grid, "nodes": math.prod(grid)}
    row["t_sample_s"] = time_per_sample(config)
    with tempfile.TemporaryDirectory() as tmp:
        generate(config.model_copy(update={"n_scenarios": 1}), Path(tmp) / "b.h5")
        row["bytes"] = bytes_per_sample(Path(tmp) / "b.h5")
    for name, engine, workers in (
        ("local1", "local", 1),
        ("local2", "local", 2),
        ("dask2", "dask", 2),
    ):
        row[name] = run_engine(config, engine, workers, repeat)
        print(f"  {grid} {name}: {row[name]:.2f} samples/s", flush=True)
    return row


def project(rows: list[dict], large: dict | None) -> dict:
    """Per-sample time and bytes at the paper's grid: measured, or a power law in node count."""
    n_l = math.prod(PAPER_GRID)
    if large is not None:
        return {"how": "measured at 64x64x128", "t": large["t_sample_s"], "bytes": large["bytes"]}
    a, b = rows[-2], rows[-1]
    k_t = math.log(b["t_sample_s"] / a["t_sample_s"]) / math.log(b["nodes"] / a["nodes"])
    k_b = math.log(b["bytes"] / a["bytes"]) / math.log(b["nodes"] / a["nodes"])
    return {
        "how": f"extrapolated from {a['grid']} and {b['grid']} (time ~ n^{k_t:.2f}, bytes ~ n^{k_b:.2f})",
        "t": b["t_sample_s"] * (n_l / b["nodes"]) ** k_t,
        "bytes": b["bytes"] * (n_l / b["nodes"]) ** k_b,
    }


def table(rows: list[dict], proj: dict, args: argparse.Namespace) -> str:
    lines = [
        "# Dataset generation (Algorithm 1)",
        "",
        f"`python benchmarks/datagen.py {' '.join(sys.argv[1:])}`: {args.scenarios} scenarios x "
        f"{args.steps} steps per run, median of {args.repeat}; FEM mechanics + level set per sample. "
        "Shared 2-core machine: compare the ratios.",
        "",
        "| grid (nz x ny x nx) | s per sample (1 process) | 1 local (samples/s) | 2 local | 2 local / 1 "
        "| Dask 2 workers | Dask / 2 local | compressed bytes per sample |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        g = "x".join(str(n) for n in r["grid"])
        lines.append(
            f"| {g} | {r['t_sample_s']:.3f} | {r['local1']:.2f} | {r['local2']:.2f} | "
            f"{r['local2'] / r['local1']:.2f} | {r['dask2']:.2f} | {r['dask2'] / r['local2']:.2f} | "
            f"{r['bytes'] / 1e3:.1f} kB |"
        )
    core_h = PAPER_SAMPLES * proj["t"] / 3600
    disk = PAPER_SAMPLES * proj["bytes"]
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    peak_children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1e6
    lines += [
        "",
        f"## The paper's dataset: {PAPER_SAMPLES:,} samples at 64x64x128",
        "",
        "| quantity | value |",
        "|---|---|",
        f"| per-sample time (one core) | {proj['t']:.1f} s ({proj['how']}) |",
        f"| compute | {core_h:,.0f} core-hours ({core_h / 64:,.0f} h on 64 cores) |",
        f"| disk (compressed) | {disk / 1e9:,.0f} GB ({proj['bytes'] / 1e6:.2f} MB per sample) |",
        "",
        f"Peak memory: this process {peak:.2f} GB, largest child {peak_children:.2f} GB.",
        "",
    ]
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--grids", nargs="+", type=parse_grid, default=[(17, 17, 33), (33, 33, 65)])
    p.add_argument("--scenarios", type=int, default=4)
    p.add_argument("--steps", type=int, default=3)
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--large", action="store_true", help="also time 2 samples at 64x64x128")
    args = p.parse_args()
    rows = []
    for grid in args.grids:
        print(f"grid {grid}", flush=True)
        rows.append(measure(grid, args.scenarios, args.steps, args.repeat))
    large = None
    if args.large:
        config = DatagenConfig(grid=PAPER_GRID, n_scenarios=1, n_steps=2, seed=1)
        large = {"t_sample_s": time_per_sample(config)}
        with tempfile.TemporaryDirectory() as tmp:
            generate(config, Path(tmp) / "l.h5")
            large["bytes"] = bytes_per_sample(Path(tmp) / "l.h5")
    text = table(rows, project(rows, large), args)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(text, encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
