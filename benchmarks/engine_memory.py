"""Peak memory of one simulation: build + a few steps per grid, each in a fresh child process.

    python benchmarks/engine_memory.py [--grids 9x9x17 17x17x33 ...] [--steps 4]

Two scenes per grid: electric + thermal only, and every default effect on a small hot block (so
vaporization, mechanics and dissection all run within the first steps). Memory is the child's
peak RSS (VmHWM) minus its RSS after imports. Fits bytes = base + per_node * nodes per
scene by least squares, compares with ``diathermy.engine.limits.estimate_memory_bytes`` and writes
benchmarks/results/engine_memory.md.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "server")]

SCENES = {
    "electric+thermal": ["electric", "thermal"],
    "all default effects": ["electric", "thermal", "vaporization", "mechanics", "dissection"],
}


def rss_now(key: str = "VmRSS:") -> int:
    """Current (VmRSS) or peak (VmHWM) resident bytes of this process.

    The peak is read here rather than from ``resource.getrusage``: Linux carries ``ru_maxrss``
    across exec from a forked parent, so a child of a big process would report the parent's peak.
    """
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key):
            return int(line.split()[1]) * 1024
    raise RuntimeError(f"no {key}")


def child(shape: tuple[int, int, int], effects: list[str], steps: int) -> dict[str, float]:
    """Build and step one simulation; returns bytes above the post-import baseline."""
    import time

    from diathermy.engine.simulation import Simulation
    from diathermy.runtime import configure_threads
    from diathermy.scene import scene_from_dict

    configure_threads()
    scene = scene_from_dict(
        {
            "block_m": [0.02, 0.01, 0.01],
            "grid": list(shape),
            "effects": effects,
            "electrodes": [{"position_m": [0.01, 0.005], "power_w": 200.0}],
        }
    )
    base = rss_now()
    t0 = time.perf_counter()
    sim = Simulation(scene)
    reports = sim.run(steps)
    peak = rss_now("VmHWM:")
    return {
        "bytes": float(peak - base),
        "seconds": time.perf_counter() - t0,
        "mechanics_ran": float(any(r.ran("mechanics") for r in reports)),
    }


def measure(shape: tuple[int, int, int], effects: list[str], steps: int) -> dict[str, float]:
    code = (
        f"import json, sys; sys.path[:0] = [{str(ROOT / 'server')!r}, {str(ROOT)!r}]; "
        "from benchmarks.engine_memory import child; "
        f"print(json.dumps(child({tuple(shape)!r}, {effects!r}, {steps})))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=600
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def parse_grid(text: str) -> tuple[int, int, int]:
    nz, ny, nx = (int(v) for v in text.lower().split("x"))
    return nz, ny, nx


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--grids", nargs="+", type=parse_grid, default=["9x9x17", "17x17x33", "25x25x49"]
    )
    ap.add_argument("--steps", type=int, default=4)
    args = ap.parse_args()
    grids = [g if isinstance(g, tuple) else parse_grid(g) for g in args.grids]

    from diathermy.engine.limits import estimate_memory_bytes

    rows = []
    for label, effects in SCENES.items():
        for shape in grids:
            m = measure(shape, effects, args.steps)
            nodes = int(np.prod(shape))
            est = estimate_memory_bytes(shape, effects)
            rows.append((label, shape, nodes, m, est))
            print(label, shape, f"{m['bytes'] / 2**20:.1f} MiB", f"est {est / 2**20:.1f} MiB")

    lines = [
        "# Engine memory per session",
        "",
        f"`python benchmarks/engine_memory.py --grids {' '.join('x'.join(map(str, g)) for g in grids)} "
        f"--steps {args.steps}`: each row is a fresh process that builds one simulation and takes "
        f"{args.steps} steps (2 x 1 x 1 cm block, 200 W, so every called effect runs); memory is "
        "peak RSS (VmHWM) minus RSS after imports. Shared 2-core machine. The estimate is "
        "`diathermy.engine.limits.estimate_memory_bytes`, which the service checks grids with.",
        "",
        "| scene | grid | nodes | measured MiB | estimate MiB | estimate / measured | mechanics ran | s |",
        "|---|---|---:|---:|---:|---:|---|---:|",
    ]
    for label, shape, nodes, m, est in rows:
        lines.append(
            f"| {label} | {'x'.join(map(str, shape))} | {nodes} | {m['bytes'] / 2**20:.1f} | "
            f"{est / 2**20:.1f} | {est / max(m['bytes'], 1):.2f} | "
            f"{'yes' if m['mechanics_ran'] else 'no'} | {m['seconds']:.1f} |"
        )
    lines += ["", "Least-squares fits, bytes = base + per_node * nodes:", ""]
    for label in SCENES:
        sel = [(n, m["bytes"]) for lab, _, n, m, _ in rows if lab == label]
        A = np.array([[1.0, n] for n, _ in sel])
        b = np.array([v for _, v in sel])
        (base, per_node), *_ = np.linalg.lstsq(A, b, rcond=None)
        lines.append(f"- {label}: base {base / 2**20:.1f} MiB, {per_node:.0f} bytes per node")
    lines.append("")
    out = ROOT / "benchmarks" / "results" / "engine_memory.md"
    out.write_text("\n".join(lines), encoding="utf-8")
    print(out.read_text())


if __name__ == "__main__":
    main()
