"""Grid convergence under the electrode (issue #21): the fixed electrode on graded grids of
halving fine spacing, the paper's moving electrode, and today's uniform 33x33x65 beside them.

    python benchmarks/convergence.py run --fine-mm 1 --seconds 3            # one fixed run
    python benchmarks/convergence.py run --fine-mm 0 --seconds 3            # uniform 33x33x65
    python benchmarks/convergence.py run --fine-mm 1 --moving --seconds 12  # moving, 12.35 mm/s
    python benchmarks/convergence.py report                                 # table + plot

``run`` steps the fixed-electrode scene (current-density drive, 5.72e4 A/m^2 over the 1.17 mm
disk, all effects) on a graded grid (``scene.resolution``: fine cells over the contact +- margin,
3 mm deep, growth 1.25, cells <= 6.25 mm), stops at ``--seconds`` of simulated time or
``--wall-limit`` seconds of wall time, and saves per-step records and crater profiles to
``benchmarks/results/convergence_<tag>.npz``. ``report`` writes ``convergence.md`` and
``convergence.png`` (crater profile per resolution) from every saved run.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import math  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "server"))

from diathermy.engine.simulation import Simulation  # noqa: E402
from diathermy.physics.contact_resistance import (  # noqa: E402
    block_image_resistance,
    equipotential_disk_resistance,
    uniform_flux_disk_resistance,
)
from diathermy.physics.topology import contact_height  # noqa: E402
from diathermy.scene import Scene, builtin_scene  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
PROFILE_TIMES_S = (3.0, 6.0, 12.0)
"""Simulated times at which the crater profile is saved."""
PROFILE_HALF_WIDTH_M = 6e-3
T_BOIL_K = 373.15


def scene_for(fine_mm: float, *, moving: bool, drive: str = "current_density") -> Scene:
    """The fixed (or moving) electrode scene on a graded grid of ``fine_mm`` (0: uniform)."""
    base = builtin_scene("moving-electrode" if moving else "fixed-electrode").model_dump()
    base["electrodes"][0]["drive"] = drive
    base["resolution"] = {"fine_m": fine_mm * 1e-3} if fine_mm > 0 else None
    return Scene.model_validate(base)


def tag_of(fine_mm: float, moving: bool) -> str:
    kind = "moving" if moving else "fixed"
    return f"{kind}_{'uniform' if fine_mm <= 0 else f'{fine_mm:g}mm'}"


def crater_profile(sim: Simulation, centre: tuple[float, float]) -> np.ndarray:
    """Depth (m) of the healthy surface below the top along x through the contact (201 points)."""
    xs = centre[0] + np.linspace(-PROFILE_HALF_WIDTH_M, PROFILE_HALF_WIDTH_M, 201)
    z = contact_height(sim.state["level_set"], sim.grid, xs, np.full(xs.shape, centre[1]))
    return sim.ctx.top_z - np.asarray(z)


def run(fine_mm: float, *, moving: bool, seconds: float, wall_limit: float) -> Path:
    scene = scene_for(fine_mm, moving=moving)
    t0 = time.perf_counter()
    sim = Simulation(scene)
    build_s = time.perf_counter() - t0
    centre = scene.electrodes[0].position_m
    keys = ("time_s", "wall_s", "power_w", "t_max_k", "p_max_pa", "w_max", "cut_m3", "depth_m")
    rec: dict[str, list[float]] = {k: [] for k in keys}
    profiles: dict[str, np.ndarray] = {}
    n_steps = round(seconds / scene.dt_s)
    started = time.perf_counter()
    for _ in range(n_steps):
        r = sim.step()
        for k, v in zip(
            keys,
            (
                r.time_s,
                r.wall_s,
                r.delivered_power_w,
                r.max_temperature_k,
                r.max_pressure_pa,
                r.max_strain_energy_j_per_m3,
                r.cut_volume_m3,
                r.crater_depth_m,
            ),
            strict=True,
        ):
            rec[k].append(float(v))
        for t in PROFILE_TIMES_S:
            if abs(r.time_s - t) < 0.5 * scene.dt_s and not moving:
                profiles[f"profile_{t:g}s"] = crater_profile(sim, centre)
        if time.perf_counter() - started > wall_limit:
            break
    if not moving:
        profiles["profile_end"] = crater_profile(sim, centre)
    out = RESULTS / f"convergence_{tag_of(fine_mm, moving)}.npz"
    np.savez(
        out,
        **{k: np.asarray(v) for k, v in rec.items()},
        **profiles,
        fine_mm=fine_mm,
        moving=moving,
        shape=np.asarray(sim.grid.shape),
        n_nodes=sim.grid.n_nodes,
        build_s=build_s,
        max_rss_mib=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        target_s=seconds,
    )
    print(f"{out.name}: {len(rec['time_s'])} steps to t = {rec['time_s'][-1]:.2f} s")
    return out


def _first(time_s: np.ndarray, mask: np.ndarray) -> float:
    idx = np.flatnonzero(mask)
    return float(time_s[idx[0]]) if idx.size else math.nan


def _at(time_s: np.ndarray, values: np.ndarray, t: float) -> float:
    idx = np.flatnonzero(np.abs(time_s - t) < 1e-6)
    return float(values[idx[0]]) if idx.size else math.nan


def _fmt(v: float, scale: float = 1.0, digits: int = 2) -> str:
    return "—" if not math.isfinite(v) else f"{v * scale:.{digits}f}"


def summary(d: dict[str, np.ndarray]) -> dict[str, float]:
    t = d["time_s"]
    return {
        "t_end": float(t[-1]),
        "t100": _first(t, d["t_max_k"] >= T_BOIL_K),
        "first_cut": _first(t, d["cut_m3"] > 0),
        "cut3": _at(t, d["cut_m3"], 3.0),
        "depth3": _at(t, d["depth_m"], 3.0),
        "cut6": _at(t, d["cut_m3"], 6.0),
        "depth6": _at(t, d["depth_m"], 6.0),
        "cut12": _at(t, d["cut_m3"], 12.0),
        "depth12": _at(t, d["depth_m"], 12.0),
        "p_peak": float(d["p_max_pa"].max()),
        "power0": float(d["power_w"][0]),
        "step_median": float(np.median(d["wall_s"][1:] if t.size > 1 else d["wall_s"])),
        "rss": float(d["max_rss_mib"]),
        "nodes": float(d["n_nodes"]),
    }


def observed_order(a: float, b: float, c: float) -> float:
    """Order p from three values at spacings h, h/2, h/4: log2(|a - b| / |b - c|)."""
    if not all(math.isfinite(v) for v in (a, b, c)) or b == c or a == b:
        return math.nan
    return math.log2(abs(a - b) / abs(b - c))


def report() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = {
        p.stem.removeprefix("convergence_"): dict(np.load(p))
        for p in RESULTS.glob("convergence_*.npz")
    }
    fixed = sorted(
        (k for k in runs if k.startswith("fixed")),
        key=lambda k: -float(runs[k]["fine_mm"]) if float(runs[k]["fine_mm"]) > 0 else -1e9,
    )
    moving = sorted(
        (k for k in runs if k.startswith("moving")), key=lambda k: -float(runs[k]["fine_mm"])
    )
    current = 5.72e4 * math.pi * 1.17e-3**2
    eq_w = current**2 * equipotential_disk_resistance(0.33, 1.17e-3)
    ref_w = current**2 * (
        uniform_flux_disk_resistance(0.33, 1.17e-3)
        + block_image_resistance(0.33, (0.2, 0.1, 0.1), (0.0, 0.0, 0.0), (0.1, 0.05))
    )
    lines = [
        "# Grid convergence under the electrode (issue #21)",
        "",
        "`python benchmarks/convergence.py run --fine-mm F --seconds S` per row, then "
        "`python benchmarks/convergence.py report`. Fixed electrode, current-density drive "
        "(5.72e4 A/m^2 over the 1.17 mm disk, I = 0.246 A), all effects, dt 0.03 s; graded grids: "
        "fine cells over the contact +- 4.17 mm (radius + 3 mm margin), 3 mm deep, growth 1.25, "
        "cells <= 6.25 mm. A run stops at its simulated target or its wall limit (t end). "
        "Shared 2-core machine, single-threaded BLAS: read step times as ratios.",
        "",
        f"Resolved-contact references: the issue's equipotential disk I^2 / (4 sigma a) = "
        f"{eq_w:.2f} W; this drive's limit (uniform current density, 8 I^2 / (3 pi^2 sigma a), "
        f"plus the block's own resistance by images) = {ref_w:.2f} W (`P / ref` uses it).",
        "",
        "| grid | nodes | t end s | P W (step 1) | P / ref | t 100 C s | first cut s | cut 3 s mm^3 "
        "| depth 3 s mm | cut 6 s mm^3 | depth 6 s mm | peak p kPa | median step s | max RSS MiB |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    sums = {k: summary(runs[k]) for k in runs}
    for k in fixed:
        s, sh = sums[k], "x".join(str(n) for n in runs[k]["shape"])
        lines.append(
            f"| {k.removeprefix('fixed_')} ({sh}) | {s['nodes']:.0f} | {s['t_end']:.2f} | "
            f"{s['power0']:.2f} | {s['power0'] / ref_w:.3f} | {_fmt(s['t100'])} | "
            f"{_fmt(s['first_cut'])} | {_fmt(s['cut3'], 1e9)} | {_fmt(s['depth3'], 1e3)} | "
            f"{_fmt(s['cut6'], 1e9)} | {_fmt(s['depth6'], 1e3)} | {s['p_peak'] / 1e3:.0f} | "
            f"{s['step_median']:.2f} | {s['rss']:.0f} |"
        )
    graded = [k for k in fixed if float(runs[k]["fine_mm"]) > 0]
    if graded:  # every run at the time the shortest one reached
        tc = min(sums[k]["t_end"] for k in graded)
        lines += [
            "",
            f"At t = {tc:.2f} s, the last time every graded run reached:",
            "",
            "| grid | cut mm^3 | depth mm | cut / finest |",
            "|---|---:|---:|---:|",
        ]
        fin = _at(runs[graded[-1]]["time_s"], runs[graded[-1]]["cut_m3"], tc)
        for k in fixed:
            d = runs[k]
            cut, depth = _at(d["time_s"], d["cut_m3"], tc), _at(d["time_s"], d["depth_m"], tc)
            rel = cut / fin if fin else math.nan
            lines.append(
                f"| {k.removeprefix('fixed_')} | {_fmt(cut, 1e9)} | {_fmt(depth, 1e3)} | "
                f"{_fmt(rel, 1.0, 3)} |"
            )
        lines += [
            "",
            "First-cut times are whole steps (dt 0.03 s): 0.06 and 0.09 s differ by one step.",
        ]
    if len(graded) >= 3:
        a, b, c = (sums[k] for k in graded[-3:])
        lines += [
            "",
            f"Observed order over the three finest graded runs ({', '.join(graded[-3:])}): "
            f"P {observed_order(a['power0'], b['power0'], c['power0']):.2f}, first cut "
            f"{observed_order(a['first_cut'], b['first_cut'], c['first_cut']):.2f}, cut volume at 3 s "
            f"{observed_order(a['cut3'], b['cut3'], c['cut3']):.2f} (NaN: a value missing or equal).",
        ]
    if graded:
        finest = sums[graded[-1]]
        lines += ["", f"Relative to the finest run ({graded[-1]}):", ""]
        lines += ["| grid | P | first cut | cut volume 3 s |", "|---|---:|---:|---:|"]
        for k in fixed:
            s = sums[k]
            rel = [
                s[q] / finest[q] - 1 if finest[q] and math.isfinite(finest[q]) else math.nan
                for q in ("power0", "first_cut", "cut3")
            ]
            lines.append(
                f"| {k.removeprefix('fixed_')} | "
                + " | ".join(_fmt(v, 100, 1) + " %" for v in rel)
                + " |"
            )
    if moving:
        lines += [
            "",
            "Moving electrode (the paper's path at 12.35 mm/s, current-density drive):",
            "",
            "| grid | nodes | t end s | first cut s | cut at t end mm^3 | depth at t end mm "
            "| cut 6 s mm^3 | depth 6 s mm | cut 12 s mm^3 | depth 12 s mm | peak p kPa "
            "| median step s | max RSS MiB |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for k in moving:
            s = sums[k]
            lines.append(
                f"| {k.removeprefix('moving_')} | {s['nodes']:.0f} | {s['t_end']:.2f} | "
                f"{_fmt(s['first_cut'])} | {_fmt(float(runs[k]['cut_m3'][-1]), 1e9)} | "
                f"{_fmt(float(runs[k]['depth_m'][-1]), 1e3)} | "
                f"{_fmt(s['cut6'], 1e9)} | {_fmt(s['depth6'], 1e3)} | {_fmt(s['cut12'], 1e9)} | "
                f"{_fmt(s['depth12'], 1e3)} | {s['p_peak'] / 1e3:.0f} | {s['step_median']:.2f} | "
                f"{s['rss']:.0f} |"
            )
    (RESULTS / "convergence.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    fig, ax = plt.subplots(figsize=(7, 4))
    xs = np.linspace(-PROFILE_HALF_WIDTH_M, PROFILE_HALF_WIDTH_M, 201) * 1e3
    for k in fixed:
        d = runs[k]
        key = "profile_3s" if "profile_3s" in d else "profile_end"
        when = "3 s" if key == "profile_3s" else f"t = {float(d['time_s'][-1]):.2f} s"
        label = f"{k.removeprefix('fixed_')} ({when})"
        ax.plot(xs, -np.asarray(d[key]) * 1e3, label=label)
    ax.set_xlabel("x - x_contact (mm)")
    ax.set_ylabel("healthy surface below the top (mm)")
    ax.set_title("Crater profile through the fixed electrode")
    ax.legend()
    fig.tight_layout()
    fig.savefig(RESULTS / "convergence.png", dpi=110)
    print((RESULTS / "convergence.md").read_text())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--fine-mm", type=float, required=True, help="fine spacing; 0: uniform 33x33x65")
    r.add_argument("--moving", action="store_true")
    r.add_argument("--seconds", type=float, default=3.0)
    r.add_argument("--wall-limit", type=float, default=3600.0)
    sub.add_parser("report")
    a = ap.parse_args(argv)
    if a.cmd == "run":
        run(a.fine_mm, moving=a.moving, seconds=a.seconds, wall_limit=a.wall_limit)
    else:
        report()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
