"""The fixed-electrode crater against its fine region (issue #21).

The ``fixed-electrode`` scene (50 W power drive, 12 s) on its graded grid without a deep tier
(0.4 mm over the contact + 2 mm, 12 mm deep: the shipped grid until 2026-12-07) drills below its
working region long before its 12 s. This runs the scene without and with a deep tier under the
region (``resolution.deep_m``: cells of the region's width, at most ``deep_z_m`` tall, down to
that depth; the scene ships 90 mm), each grid in a process of its own, one after the other, and
compares the craters at common times.

    python benchmarks/fixed_depth.py run --deep-mm 0 90          # no tier, then a 90 mm one
    python benchmarks/fixed_depth.py run --deep-mm 90 --seconds 6
    python benchmarks/fixed_depth.py report                      # fixed_depth.md from every run

``run`` saves per step the delivered power, the cut volume, the crater depth and how far the cut
reaches beyond the (tiered) fine region to ``benchmarks/results/fixed_depth_<tag>.json``;
``report`` writes ``benchmarks/results/fixed_depth.md``: per run the nodes, the median step and
the peak memory, the time the cut first left the fine region, and the crater at 1.5 / 3 / 6 / 9 /
12 s beside the deepest run's.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import multiprocessing as mp  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from datetime import UTC, datetime  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "server"))

from diathermy.engine.simulation import Simulation  # noqa: E402
from diathermy.runtime import configure_threads, own_peak_rss_mib  # noqa: E402
from diathermy.scene import Scene, builtin_scene  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
TIMES_S = (1.5, 3.0, 6.0, 9.0, 12.0)
"""Simulated times at which the report compares the craters."""


def scene_for(deep_mm: float, base: str = "fixed-electrode") -> Scene:
    """The built-in scene with a deep tier down to ``deep_mm`` below the top (0: none), its
    region's cells up to the surface (the recorded runs; the scene refines its top cells to
    0.1 mm since 2026-12-07: +0.5 % crater volume, +3.7 % depth at 1.5 s, docs/resolution.md)."""
    data = builtin_scene(base).model_dump()
    deep = deep_mm * 1e-3 if deep_mm > 0 else None
    data["resolution"] = {**data["resolution"], "deep_m": deep, "surface_m": None}
    return Scene.model_validate(data)


def tag_of(deep_mm: float) -> str:
    return "notier" if deep_mm <= 0 else f"deep{deep_mm:g}"


def run_one(
    deep_mm: float, seconds: float, out_dir: Path, command: str = "", base: str = "fixed-electrode"
) -> Path:
    """Step the scene for ``seconds`` of simulated time; the per-step records as JSON."""
    started = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    configure_threads()
    scene = scene_for(deep_mm, base)
    t0 = time.perf_counter()
    sim = Simulation(scene)
    build_s = time.perf_counter() - t0
    steps: list[dict[str, float]] = []
    bar = tqdm(range(round(seconds / scene.dt_s)), desc=tag_of(deep_mm), unit="step")
    for _ in bar:
        r = sim.step()
        bar.set_postfix_str(f"{r.cut_volume_m3 * 1e9:.1f} mm^3, {r.crater_depth_m * 1e3:.1f} mm")
        steps.append(
            {
                "time_s": r.time_s,
                "wall_s": r.wall_s,
                "power_w": r.delivered_power_w,
                "cut_m3": r.cut_volume_m3,
                "depth_m": r.crater_depth_m,
                "beyond_m": r.beyond_fine_region_m.get("cut", 0.0),
            }
        )
    region = scene.working_region()
    out = out_dir / f"fixed_depth_{tag_of(deep_mm)}.json"
    out.write_text(
        json.dumps(
            {
                "scene": scene.name,
                "command": command,
                "started": started,
                "deep_mm": deep_mm,
                "resolution": scene.resolution.model_dump(mode="json")
                if scene.resolution
                else None,
                "region_bottom_mm": (scene.block_m[2] - region[0][2]) * 1e3 if region else None,
                "shape": list(sim.grid.shape),
                "nodes": sim.grid.n_nodes,
                "build_s": build_s,
                "peak_mib": own_peak_rss_mib(),
                "steps": steps,
            }
        ),
        encoding="utf-8",
    )
    print(f"{out.name}: {len(steps)} steps, {sim.grid.n_nodes} nodes", flush=True)
    return out


def at(steps: list[dict[str, float]], t: float, key: str) -> float | None:
    """The record ``key`` at the step nearest simulated time ``t`` (None past the run's end)."""
    times = np.array([s["time_s"] for s in steps])
    if times.size == 0 or t > times[-1] + 1e-9:
        return None
    return float(steps[int(np.argmin(np.abs(times - t)))][key])


def left_at(steps: list[dict[str, float]]) -> float | None:
    """The first simulated time the cut reached beyond the fine region (None: never)."""
    return next((s["time_s"] for s in steps if s["beyond_m"] > 0), None)


def report(out_dir: Path = RESULTS) -> Path:
    """``fixed_depth.md`` from every saved run in ``out_dir``."""
    runs = [json.loads(p.read_text()) for p in sorted(out_dir.glob("fixed_depth_*.json"))]
    if not runs:
        raise SystemExit(f"no fixed_depth_*.json in {out_dir}: run first")
    runs.sort(key=lambda r: r["deep_mm"])
    ref = runs[-1]
    commands = dict.fromkeys(r["command"] for r in runs)  # one line per command, in order
    made = "; ".join(
        f"`{c}` (runs started {', '.join(r['started'] for r in runs if r['command'] == c)})"
        for c in commands
    )
    lines = [
        "# The fixed electrode's crater against its fine region (issue #21)",
        "",
        f"{made}, then `report`; "
        "the `fixed-electrode` scene (50 W power drive, dt 0.03 s) on its graded grid without a "
        "deep tier (`notier`: 0.4 mm over the contact + 2 mm, 12 mm deep, the shipped grid until "
        "2026-12-07) and with a deep tier under that region "
        "(`resolution.deep_m`: cells 0.4 mm wide and at most 0.8 mm tall down to that depth). "
        "Each run in a process of its own, one after the other, on a shared 2-core machine: read "
        "step times as ratios.",
        "",
        "| grid | nodes | fine region to | median step s | peak MiB | cut leaves it at s |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for r in runs:
        med = float(np.median([s["wall_s"] for s in r["steps"]]))
        left = left_at(r["steps"])
        lines.append(
            f"| {tag_of(r['deep_mm'])} {'x'.join(map(str, r['shape']))} | {r['nodes']:,} | "
            f"{r['region_bottom_mm']:.1f} mm | {med:.2f} | {r['peak_mib']:.0f} | "
            f"{'-' if left is None else f'{left:.2f}'} |"
        )
    lines += [
        "",
        f"Crater volume (mm^3), depth (mm) and how far the cut reaches beyond the fine region "
        f"(mm), and the volume and depth against the `{tag_of(ref['deep_mm'])}` run:",
        "",
        "| t s | grid | volume | depth | beyond | volume / ref | depth / ref |",
        "|---:|---|---:|---:|---:|---:|---:|",
    ]
    for t in TIMES_S:
        v_ref, d_ref = at(ref["steps"], t, "cut_m3"), at(ref["steps"], t, "depth_m")
        for r in runs:
            v, d, b = (at(r["steps"], t, k) for k in ("cut_m3", "depth_m", "beyond_m"))
            if v is None or d is None or b is None:
                continue
            rv = f"{v / v_ref:.3f}" if v_ref else "-"
            rd = f"{d / d_ref:.3f}" if d_ref else "-"
            lines.append(
                f"| {t:g} | {tag_of(r['deep_mm'])} | {v * 1e9:.1f} | {d * 1e3:.2f} | "
                f"{b * 1e3:.2f} | {rv} | {rd} |"
            )
    out = out_dir / "fixed_depth.md"
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"wrote {out}")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--deep-mm", type=float, nargs="+", default=[0.0, 90.0])
    r.add_argument("--seconds", type=float, default=12.0)
    r.add_argument("--out", type=Path, default=RESULTS)
    p = sub.add_parser("report")
    p.add_argument("--out", type=Path, default=RESULTS)
    a = ap.parse_args(argv)
    if a.cmd == "report":
        report(a.out)
        return 0
    if any(d < 0 for d in a.deep_mm) or a.seconds <= 0:
        ap.error("--deep-mm must be >= 0 and --seconds > 0")
    a.out.mkdir(parents=True, exist_ok=True)
    command = "python benchmarks/fixed_depth.py " + " ".join(sys.argv[1:] if argv is None else argv)
    ctx = mp.get_context("spawn")
    for deep in a.deep_mm:
        proc = ctx.Process(target=run_one, args=(deep, a.seconds, a.out, command))
        proc.start()
        proc.join()
        if proc.exitcode != 0:
            raise SystemExit(f"the run with --deep-mm {deep:g} failed (exit {proc.exitcode})")
    report(a.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
