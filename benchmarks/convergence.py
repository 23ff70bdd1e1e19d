"""Grid convergence under the electrode (issue #21): the fixed electrode on graded grids of
halving fine spacing, the paper's moving electrode, and the uniform 33x33x65 beside them.

    python benchmarks/convergence.py run --fine-mm 0.4 --seconds 3          # one fixed run
    python benchmarks/convergence.py run --fine-mm 0 --seconds 3            # uniform 33x33x65
    python benchmarks/convergence.py run --fine-mm 0.8 --dt 0.015 --seconds 0.4  # dt study
    python benchmarks/convergence.py run --moving --seconds 12              # moving, its grid
    python benchmarks/convergence.py power --fine-mm 0.8 0.4 0.2 0.1        # step-1 power only
    python benchmarks/convergence.py main-job                               # default vs uniform
    python benchmarks/convergence.py probe --fine-mm 0.8 0.4 --steps 40     # under the contact
    python benchmarks/convergence.py run --fine-mm 0.4 --surface-mm 0.1      # surface-refined
    python benchmarks/convergence.py cost --fine-mm 0.4 --surface-mm 0.1     # its step cost
    python benchmarks/convergence.py report                                 # table + plot

``run`` steps the fixed-electrode scene (current-density drive, 5.72e4 A/m^2 over the 1.17 mm
disk, all effects) on its graded grid (``scene.resolution``: fine cells over the contact + 2 mm,
12 mm deep, growth 1.25, cells <= 6.25 mm) with ``fine_m`` set to ``--fine-mm``, or the
``moving-electrode`` scene as shipped (50 W, 12.35 mm/s, its own grid); it stops at ``--seconds``
of simulated time or ``--wall-limit`` seconds of wall time and saves per-step records and crater
profiles to ``benchmarks/results/convergence_<tag>.npz``. Besides the step at which the tissue
first passes 100 C and first cuts, each run records the time within the step at which the cut
criterion is crossed: the largest strain energy on the front's nodes (the nodal W that drives the
level set, PHYSICS.md section 4) reaching kappa, linear in time between the two steps that
bracket it (likewise T passing 100 C). ``power`` measures the delivered power of the first step
alone (electric only). ``main-job`` runs the ``default`` scene (50 W) on its grid and on the
uniform 33x33x65, each in its own process (so each max RSS is its own). ``report`` writes
``convergence.md`` and ``convergence.png`` (crater profile per resolution) from every saved run.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import multiprocessing as mp  # noqa: E402
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
from diathermy.physics.dissection import cut_driver  # noqa: E402
from diathermy.physics.topology import contact_height  # noqa: E402
from diathermy.scene import Scene, builtin_scene  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
PROFILE_TIMES_S = (3.0, 6.0, 12.0)
"""Simulated times at which the crater profile is saved."""
PROFILE_HALF_WIDTH_M = 6e-3
T_BOIL_K = 373.15
T_INITIAL_K = 310.15


UNIFORM = (33, 33, 65)
DT_S = 0.03


def scene_for(
    fine_mm: float | None,
    *,
    moving: bool,
    dt_s: float = DT_S,
    length_mm: float | None = None,
    contact: str | None = None,
    surface_mm: float | None = None,
) -> Scene:
    """The fixed electrode (current-density drive) with its resolution at ``fine_mm`` (0: uniform
    33x33x65), or the moving electrode as shipped (``fine_mm`` None: its own grid); the cut
    driver's non-local length at ``length_mm``, the electrode's contact model at ``contact`` and
    the cell height at the top surface at ``surface_mm`` (None: the scene's; 0: fine_mm)."""
    scene = builtin_scene("moving-electrode" if moving else "fixed-electrode")
    if fine_mm is not None and fine_mm <= 0:
        scene = scene.on_uniform_grid(UNIFORM)
    base = scene.model_dump()
    if not moving:
        base["electrodes"][0]["drive"] = "current_density"
    if fine_mm is not None and fine_mm > 0:
        base["resolution"] = {**base["resolution"], "fine_m": fine_mm * 1e-3}
    base["dt_s"] = dt_s
    if length_mm is not None:
        base["level_set"] = {**base["level_set"], "nonlocal_length_m": length_mm * 1e-3}
    if contact is not None:
        base["electrodes"] = [{**e, "contact": contact} for e in base["electrodes"]]
    if surface_mm is not None and base.get("resolution") is not None:
        surface = surface_mm * 1e-3 if surface_mm > 0 else None
        base["resolution"] = {**base["resolution"], "surface_m": surface}
    return Scene.model_validate(base)


def tag_of(
    fine_mm: float | None,
    moving: bool,
    dt_s: float = DT_S,
    length_mm: float = 0.0,
    contact: str = "flat",
    surface_mm: float = 0.0,
) -> str:
    """The run's file tag: scene, grid, dt if not the default, the non-local length if any, the
    contact model if not flat, the surface cell if refined."""
    kind = "moving" if moving else "fixed"
    grid = "default" if fine_mm is None else "uniform" if fine_mm <= 0 else f"{fine_mm:g}mm"
    tag = f"{kind}_{grid}" + ("" if dt_s == DT_S else f"_dt{dt_s:g}")
    tag += f"_l{length_mm:g}" if length_mm > 0 else ""
    tag += "" if contact == "flat" else f"_{contact}"
    return tag + (f"_s{surface_mm:g}" if surface_mm > 0 else "")


def front_strain_energy(sim: Simulation) -> float:
    """The largest nodal strain energy (J/m^3) driving the front (``cut_driver``, the scene's
    non-local length) on its nodes (phi <= 0): what starts a cut."""
    W = sim.state["strain_energy"]
    if not W.any():
        return 0.0
    W_nodes = cut_driver(
        W,
        sim.state["removed"],
        mesh=sim.disc.mesh,
        grid=sim.grid,
        volumes=sim.disc.geom.volumes,
        incidence=sim.ctx.incidence,
        length_m=sim.scene.level_set.nonlocal_length_m,
    )
    front = sim.state["level_set"] <= 0.0
    return float(W_nodes[front].max()) if front.any() else 0.0


def crater_profile(sim: Simulation, centre: tuple[float, float]) -> np.ndarray:
    """Depth (m) of the healthy surface below the top along x through the contact (201 points)."""
    xs = centre[0] + np.linspace(-PROFILE_HALF_WIDTH_M, PROFILE_HALF_WIDTH_M, 201)
    z = contact_height(sim.state["level_set"], sim.grid, xs, np.full(xs.shape, centre[1]))
    return sim.ctx.top_z - np.asarray(z)


def run(
    fine_mm: float | None,
    *,
    moving: bool,
    seconds: float,
    wall_limit: float,
    dt_s: float = DT_S,
    length_mm: float | None = None,
    contact: str | None = None,
    surface_mm: float | None = None,
) -> Path:
    scene = scene_for(
        fine_mm, moving=moving, dt_s=dt_s, length_mm=length_mm, contact=contact,
        surface_mm=surface_mm,
    )  # fmt: skip
    length_mm = scene.level_set.nonlocal_length_m * 1e3
    contact = scene.electrodes[0].contact
    res = scene.resolution
    surface_mm = res.surface_m * 1e3 if res is not None and res.surface_m is not None else 0.0
    t0 = time.perf_counter()
    sim = Simulation(scene)
    build_s = time.perf_counter() - t0
    centre = scene.electrodes[0].position_m
    keys = (
        "time_s",
        "wall_s",
        "power_w",
        "t_max_k",
        "p_max_pa",
        "w_max",
        "w_front",
        "cut_m3",
        "depth_m",
    )
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
                front_strain_energy(sim),
                r.cut_volume_m3,
                r.crater_depth_m,
            ),
            strict=True,
        ):
            rec[k].append(float(v))
        for t in PROFILE_TIMES_S:
            if abs(r.time_s - t) < 0.5 * scene.dt_s and not moving and dt_s == DT_S:
                profiles[f"profile_{t:g}s"] = crater_profile(sim, centre)
        if time.perf_counter() - started > wall_limit:
            break
    if not moving:
        profiles["profile_end"] = crater_profile(sim, centre)
    tag = tag_of(fine_mm, moving, dt_s, length_mm, contact, surface_mm)
    out = RESULTS / f"convergence_{tag}.npz"
    np.savez(
        out,
        **{k: np.asarray(v) for k, v in rec.items()},
        **profiles,
        fine_mm=res.fine_m * 1e3 if res is not None else 0.0,
        depth_mm=res.depth_m * 1e3 if res is not None else 0.0,
        dt_s=scene.dt_s,
        kappa=sim.tissue.damage_kappa_j_per_m3,
        moving=moving,
        shape=np.asarray(sim.grid.shape),
        n_nodes=sim.grid.n_nodes,
        build_s=build_s,
        max_rss_mib=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        target_s=seconds,
        length_mm=length_mm,
        contact=contact,
        surface_mm=surface_mm,
    )
    print(f"{out.name}: {len(rec['time_s'])} steps to t = {rec['time_s'][-1]:.2f} s")
    return out


def _first(time_s: np.ndarray, mask: np.ndarray) -> float:
    idx = np.flatnonzero(mask)
    return float(time_s[idx[0]]) if idx.size else math.nan


def crossing(time_s: np.ndarray, values: np.ndarray, level: float, start: float) -> float:
    """Time (s) at which ``values`` first reach ``level``, linear between the bracketing steps
    (the state at t = 0 has ``start``); NaN if never."""
    idx = np.flatnonzero(values >= level)
    if not idx.size:
        return math.nan
    i = int(idx[0])
    t0, v0 = (0.0, start) if i == 0 else (float(time_s[i - 1]), float(values[i - 1]))
    t1, v1 = float(time_s[i]), float(values[i])
    return t1 if v1 == v0 else t0 + (level - v0) / (v1 - v0) * (t1 - t0)


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
        "t100_interp": crossing(t, d["t_max_k"], T_BOIL_K, T_INITIAL_K),
        "first_cut": _first(t, d["cut_m3"] > 0),
        "cut_interp": crossing(t, d["w_front"], float(d["kappa"]), 0.0)
        if "w_front" in d
        else math.nan,
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


def floor_probe(fine_mm: float, steps: int) -> Path:
    """The fixed electrode on one grid: per step, the node under the contact's centre at the
    crater floor (its temperature and whether it was just uncovered) and the Joule power in the
    disk's column by depth below the floor; JSON in results (``convergence_probe.json``)."""
    scene = scene_for(fine_mm, moving=False, length_mm=0.0)
    sim = Simulation(scene)
    g = sim.grid
    x, y = scene.electrodes[0].position_m
    ix = int(np.argmin(np.abs(g.axes()[0] - x)))
    iy = int(np.argmin(np.abs(g.axes()[1] - y)))
    mesh, vol = sim.disc.mesh, sim.disc.geom.volumes
    centroids = mesh.points[mesh.tets].mean(axis=1)
    r_xy = np.hypot(centroids[:, 0] - x, centroids[:, 1] - y)
    in_disk = r_xy < scene.electrodes[0].radius_m
    near = r_xy < 2.0 * scene.electrodes[0].radius_m  # the hole and its walls
    records, last_k = [], None
    for _ in range(steps):
        r = sim.step()
        phi = sim.state["level_set"].reshape(g.shape)[:, iy, ix]
        k = int(np.flatnonzero(phi > 0).max())
        T = sim.state["temperature"].reshape(g.shape)[:, iy, ix]
        z_floor = float(contact_height(sim.state["level_set"], g, x, y))
        below = z_floor - centroids[:, 2]
        q = sim.state["joule_heat"] * vol
        healthy = ~sim.state["removed"]
        records.append(
            {
                "time_s": r.time_s,
                "floor_depth_mm": (sim.ctx.top_z - z_floor) * 1e3,
                "floor_t_k": float(T[k]),
                "uncovered": last_k is not None and k != last_k,
                "power_w": r.delivered_power_w,
                "column_0_0.4mm_w": float(
                    q[in_disk & healthy & (below >= 0) & (below < 4e-4)].sum()
                ),
                "column_0_0.8mm_w": float(
                    q[in_disk & healthy & (below >= 0) & (below < 8e-4)].sum()
                ),
                "walls_1mm_w": float(q[near & healthy & (below < 0) & (below > -1e-3)].sum()),
            }
        )
        last_k = k
    out = RESULTS / "convergence_probe.json"
    data = json.loads(out.read_text()) if out.exists() else {}
    data[f"{fine_mm:g}"] = records
    out.write_text(json.dumps(data, indent=1), encoding="utf-8")
    return out


def _probe_lines() -> list[str]:
    """Floor-node heating rate and the power under the contact per probed grid."""
    path = RESULTS / "convergence_probe.json"
    if not path.exists():
        return []
    lines = [
        "",
        "Under the contact (`probe --fine-mm F --steps N`): the node under the contact's centre at "
        "the crater floor, from the first cut on. Heating rate: median of its temperature rise "
        "per second over the steps it stays the floor node; uncovered / cut at: its median "
        "temperature on the step it became the floor / the step before the next one did; "
        "column power: the Joule power in the tets under the disk within 0.4 / 0.8 mm of the "
        "floor; walls: in the tets within 1 mm above the floor's height and two disk radii of "
        "the axis (the hole's walls); against the delivered power, over the second half of the "
        "probed steps and on the first step (*flat*: the untouched surface). The resolved "
        "contact heats the tissue right under the disk at j0^2 / (sigma rho c) = "
        f"{5.72e4**2 / 0.33 / (1019.8 * 3441):.0f} K/s.",
        "",
        "| fine mm | steps | floor heating K/s | uncovered at K | cut at K | layer steps "
        "| column 0.4 mm W | column 0.8 mm W | walls W | delivered W | flat: column 0.8 mm W "
        "| flat: delivered W |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for fine, rec in sorted(json.loads(path.read_text()).items(), key=lambda kv: -float(kv[0])):
        cutting = [r for r in rec if r["floor_depth_mm"] > 0]
        if len(cutting) < 3:
            continue
        rates, start, end, lengths, run = [], [], [], [], 0
        for a, b in zip(cutting[:-1], cutting[1:], strict=False):
            if b["uncovered"]:
                start.append(b["floor_t_k"])
                end.append(a["floor_t_k"])
                lengths.append(run)
                run = 0
            else:
                rates.append((b["floor_t_k"] - a["floor_t_k"]) / (b["time_s"] - a["time_s"]))
                run += 1
        tail = cutting[len(cutting) // 2 :]
        lines.append(
            f"| {fine} | {len(rec)} | {np.median(rates):.0f} | "
            f"{np.median(start) if start else math.nan:.0f} | "
            f"{np.median(end) if end else math.nan:.0f} | "
            f"{np.median(lengths[1:]) + 1 if len(lengths) > 1 else math.nan:.0f} | "
            f"{np.median([r['column_0_0.4mm_w'] for r in tail]):.2f} | "
            f"{np.median([r['column_0_0.8mm_w'] for r in tail]):.2f} | "
            f"{_fmt(float(np.median([r.get('walls_1mm_w', math.nan) for r in tail])))} | "
            f"{np.median([r['power_w'] for r in tail]):.1f} | "
            f"{rec[0]['column_0_0.8mm_w']:.2f} | {rec[0]['power_w']:.1f} |"
        )
    return lines


def observed_order(a: float, b: float, c: float) -> float:
    """Order p from three values at spacings h, h/2, h/4: log2(|a - b| / |b - c|)."""
    if not all(math.isfinite(v) for v in (a, b, c)) or b == c or a == b:
        return math.nan
    return math.log2(abs(a - b) / abs(b - c))


def power(fines_mm: list[float]) -> Path:
    """Delivered power of the first step (electric only) per fine spacing; JSON in results."""
    out = RESULTS / "convergence_power.json"
    rows = json.loads(out.read_text()) if out.exists() else {}
    for fine in fines_mm:
        base = scene_for(fine, moving=False).model_dump()
        base["effects"] = ["electric"]
        sim = Simulation(Scene.model_validate(base))
        t0 = time.perf_counter()
        r = sim.step()
        rows[f"{fine:g}"] = {
            "fine_mm": fine,
            "nodes": sim.grid.n_nodes,
            "shape": list(sim.grid.shape),
            "power_w": r.delivered_power_w,
            "solve_s": time.perf_counter() - t0,
        }
        print(f"{fine:g} mm: {sim.grid.n_nodes} nodes, P = {r.delivered_power_w:.3f} W", flush=True)
        del sim
    out.write_text(json.dumps(rows, indent=1), encoding="utf-8")
    return out


def _main_job(uniform: bool, steps: int) -> dict[str, float]:
    scene = builtin_scene("default")
    if uniform:
        scene = scene.on_uniform_grid(UNIFORM)
    t0 = time.perf_counter()
    sim = Simulation(scene)
    build_s = time.perf_counter() - t0
    walls, cutting, cut_at = [], [], math.nan
    for _ in range(steps):
        r = sim.step()
        walls.append(r.wall_s)
        if math.isfinite(cut_at):
            cutting.append(r.wall_s)  # the steps after the first cut: like with like
        if r.cut_volume_m3 > 0 and not math.isfinite(cut_at):
            cut_at = r.time_s
    return {
        "grid": "x".join(map(str, sim.grid.shape)),
        "graded": not sim.grid.is_uniform,
        "nodes": sim.grid.n_nodes,
        "steps": steps,
        "build_s": build_s,
        "total_s": time.perf_counter() - t0,
        "step_median_s": float(np.median(walls)),
        "step_p90_s": float(np.percentile(walls, 90)),
        "cutting_steps": len(cutting),
        "cutting_median_s": float(np.median(cutting)) if cutting else math.nan,
        "first_cut_s": cut_at,
        "cut_m3": r.cut_volume_m3,
        "depth_m": r.crater_depth_m,
        "max_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
    }


def main_job(steps: int) -> Path:
    """The ``default`` scene on its grid and on the uniform 33x33x65, one process each."""
    ctx = mp.get_context("spawn")
    runs = []
    for uniform in (True, False):
        with ctx.Pool(1, maxtasksperchild=1) as pool:
            runs.append(pool.apply(_main_job, (uniform, steps)))
        print(runs[-1], flush=True)
    out = RESULTS / "convergence_main_job.json"
    out.write_text(json.dumps(runs, indent=1), encoding="utf-8")
    return out


def surface_cost(fine_mm: float, surface_mm: float, warm: int, steps: int) -> Path:
    """What the surface refinement costs a step: the fixed electrode (current-density drive,
    the incremental default) on the plain grid of ``fine_mm`` and on the one refined to
    ``surface_mm`` at the top, ``warm`` steps each (past the first cut), then ``steps`` steps
    each, alternating, so the shared machine's load falls on both alike."""
    sims = {
        name: Simulation(scene_for(fine_mm, moving=False, surface_mm=surface))
        for name, surface in (("plain", 0.0), ("surface", surface_mm))
    }
    for sim in sims.values():
        for _ in range(warm):
            sim.step()
    walls: dict[str, list[float]] = {k: [] for k in sims}
    effects: dict[str, dict[str, list[float]]] = {k: {} for k in sims}
    for _ in range(steps):
        for name, sim in sims.items():
            t0 = time.perf_counter()
            r = sim.step()
            walls[name].append(time.perf_counter() - t0)
            for eff, er in r.effects.items():
                effects[name].setdefault(eff, []).append(er.wall_s if er.ran else 0.0)
    rows = {
        name: {
            "surface_mm": surface,
            "shape": list(sims[name].grid.shape),
            "nodes": sims[name].grid.n_nodes,
            "median_s": float(np.median(walls[name])),
            "mean_s": float(np.mean(walls[name])),
            "effects_median_s": {e: float(np.median(v)) for e, v in effects[name].items()},
        }
        for name, surface in (("plain", 0.0), ("surface", surface_mm))
    }
    out = RESULTS / "convergence_surface_cost.json"
    out.write_text(
        json.dumps({"fine_mm": fine_mm, "warm": warm, "steps": steps, "runs": rows}, indent=1),
        encoding="utf-8",
    )
    print(f"{out.name}: median {rows['surface']['median_s'] / rows['plain']['median_s']:.2f}x")
    return out


def _cost_lines() -> list[str]:
    path = RESULTS / "convergence_surface_cost.json"
    if not path.exists():
        return []
    c = json.loads(path.read_text())
    p, r = c["runs"]["plain"], c["runs"]["surface"]
    effs = sorted(set(p["effects_median_s"]) | set(r["effects_median_s"]))
    lines = [
        "",
        f"What the surface refinement costs (`cost --fine-mm {c['fine_mm']:g} --surface-mm "
        f"{r['surface_mm']:g}`): both grids in one process, {c['warm']} steps each past the "
        f"first cut, then {c['steps']} steps each, alternating (incremental default):",
        "",
        "| grid | surface mm | nodes | median step s | mean step s | "
        + " | ".join(f"{e} s" for e in effs)
        + " |",
        "|---|---:|---:|---:|---:|" + "---:|" * len(effs),
    ]
    for q in (p, r):
        lines.append(
            f"| {'x'.join(map(str, q['shape']))} | {q['surface_mm']:g} | {q['nodes']} | "
            f"{q['median_s']:.2f} | {q['mean_s']:.2f} | "
            + " | ".join(f"{q['effects_median_s'].get(e, 0.0):.3f}" for e in effs)
            + " |"
        )
    lines.append(
        f"\nRefined / plain: median step {r['median_s'] / p['median_s']:.2f}x, mean "
        f"{r['mean_s'] / p['mean_s']:.2f}x, nodes {r['nodes'] / p['nodes']:.3f}x."
    )
    return lines


def _ref_powers() -> tuple[float, float]:
    current = 5.72e4 * math.pi * 1.17e-3**2
    eq_w = current**2 * equipotential_disk_resistance(0.33, 1.17e-3)
    ref_w = current**2 * (
        uniform_flux_disk_resistance(0.33, 1.17e-3)
        + block_image_resistance(0.33, (0.2, 0.1, 0.1), (0.0, 0.0, 0.0), (0.1, 0.05))
    )
    return eq_w, ref_w


def _grid_label(k: str, d: dict[str, np.ndarray]) -> str:
    return f"{k.split('_', 1)[1]} ({'x'.join(str(n) for n in d['shape'])})"


def _power_lines(ref_w: float) -> list[str]:
    path = RESULTS / "convergence_power.json"
    if not path.exists():
        return []
    rows = sorted(json.loads(path.read_text()).values(), key=lambda r: -r["fine_mm"])
    finest = rows[-1]
    lines = [
        "",
        "Delivered power of the first step alone (`power`, electric only, the same grids):",
        "",
        "| fine mm | grid | nodes | P W | P / ref | vs finest | vs 2x finer | electric s |",
        "|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    by_fine = {r["fine_mm"]: r for r in rows}
    for r in rows:
        half = by_fine.get(r["fine_mm"] / 2)
        rel2 = f"{100 * (r['power_w'] / half['power_w'] - 1):+.1f} %" if half else "—"
        lines.append(
            f"| {r['fine_mm']:g} | {'x'.join(map(str, r['shape']))} | {r['nodes']} | "
            f"{r['power_w']:.2f} | {r['power_w'] / ref_w:.3f} | "
            f"{100 * (r['power_w'] / finest['power_w'] - 1):+.1f} % | {rel2} | {r['solve_s']:.1f} |"
        )
    halving = [r for r in rows if by_fine.get(r["fine_mm"] / 2) and by_fine.get(r["fine_mm"] / 4)]
    for r in halving:
        a, b, c = (by_fine[r["fine_mm"] / f]["power_w"] for f in (1, 2, 4))
        lines.append(
            f"\nObserved order of P over {r['fine_mm']:g} / {r['fine_mm'] / 2:g} / "
            f"{r['fine_mm'] / 4:g} mm: {observed_order(a, b, c):.2f}."
        )
    return lines


def _contact(d: dict[str, np.ndarray]) -> str:
    """The run's contact model ('flat' for older runs)."""
    return str(d["contact"]) if "contact" in d else "flat"


def _surface_mm(d: dict[str, np.ndarray]) -> float:
    """The run's cell height at the top surface in mm (0: the fine spacing, older runs)."""
    return float(d["surface_mm"]) if "surface_mm" in d else 0.0


def _surface_lines(
    runs: dict[str, dict[str, np.ndarray]], keys: list[str], plain: list[str]
) -> list[str]:
    """The surface-refined ladder (``--surface-mm``) beside the plain one: the times to 100 C
    and to the first cut, and the crater at the times the finest refined run reached."""
    if not keys:
        return []
    keys = sorted(keys, key=lambda k: -float(runs[k]["fine_mm"]))
    top = keys[-1]
    times = [t for t in (1.62, 3.0, 6.0) if float(runs[top]["time_s"][-1]) >= t - 1e-6]
    lines = [
        "",
        "Surface-refined grids (`resolution.surface_m`, `run --surface-mm`): the same graded "
        "grids with the working region's cells shrinking by the growth ratio (1.25) toward the "
        "top surface to the given height there, so the layer under the contact that heats and "
        "boils first (its thermal diffusion length over the first 0.03 s step is ~0.07 mm) is "
        "resolved in depth. Beside each, the plain grid of the same fine spacing; ratios "
        f"against the finest refined run ({top}). The runs' step times come from different "
        "days' code: the cost of the refinement is measured below, both grids in one run.",
        "",
        "| grid | surface mm | nodes | 100 C interp. s | first cut interp. s | first cut / finest | "
        + " | ".join(f"cut {t:g} s mm^3 | / finest" for t in times)
        + " |",
        "|---|---:|---:|---:|---:|---:|" + "---:|---:|" * len(times),
    ]
    fin = summary(runs[top])
    by_fine = {float(runs[k]["fine_mm"]): k for k in plain}
    rows: list[str] = []
    for k in keys:
        for kk in (by_fine.get(float(runs[k]["fine_mm"])), k):
            if kk is None or kk in rows:
                continue
            rows.append(kk)
            d, s_ = runs[kk], summary(runs[kk])
            cells = []
            for t in times:
                cut = _at(d["time_s"], d["cut_m3"], t)
                ref = _at(runs[top]["time_s"], runs[top]["cut_m3"], t)
                cells.append(f"{_fmt(cut, 1e9)} | {_fmt(cut / ref if ref else math.nan, 1.0, 3)}")
            lines.append(
                f"| {float(d['fine_mm']):g} mm | {_surface_mm(d):g} | {int(d['n_nodes'])} | "
                f"{_fmt(s_['t100_interp'], 1.0, 4)} | {_fmt(s_['cut_interp'], 1.0, 4)} | "
                f"{_fmt(s_['cut_interp'] / fin['cut_interp'], 1.0, 3)} | "
                + " | ".join(cells)
                + " |"
            )
    if len(keys) >= 3:
        a, b, c = (summary(runs[k]) for k in keys[-3:])

        def order(q: str) -> str:
            d1, d2 = a[q] - b[q], b[q] - c[q]
            if d1 * d2 < 0:  # the finest step went the other way: no asymptotic order
                return f"not monotone ({b[q] / a[q]:.3f} then {c[q] / b[q]:.3f} of the coarser)"
            return f"{observed_order(a[q], b[q], c[q]):.2f}"

        lines.append(
            f"\nObserved order over the refined ladder ({', '.join(keys[-3:])}): 100 C "
            f"{order('t100_interp')}, first cut {order('cut_interp')}, cut volume at 3 s "
            f"{order('cut3')} (NaN: a value missing or equal)."
        )
    return lines


def _length_mm(d: dict[str, np.ndarray]) -> float:
    """The run's non-local length of the cut driver in mm (0: the local law, older runs)."""
    return float(d["length_mm"]) if "length_mm" in d else 0.0


DRILL_WINDOW_S = (0.6, 1.62)
"""Simulated times between which the crater's deepening rate is fitted (past the first layers,
within the time every fixed run reaches)."""


def drilling_rate(d: dict[str, np.ndarray]) -> float:
    """The crater's deepening rate in m/s: least-squares slope of depth over ``DRILL_WINDOW_S``."""
    t, depth = d["time_s"], d["depth_m"]
    m = (t >= DRILL_WINDOW_S[0] - 1e-9) & (t <= DRILL_WINDOW_S[1] + 1e-9)
    if m.sum() < 3 or t[-1] < DRILL_WINDOW_S[1] - 1e-9:
        return math.nan
    return float(np.polyfit(t[m], depth[m], 1)[0])


def _drilling_lines(runs: dict[str, dict[str, np.ndarray]], keys: list[str]) -> list[str]:
    """The deepening rate per graded run and the fit 1 / v = A + B h over the local-law runs."""
    rows = [(k, float(runs[k]["fine_mm"]), drilling_rate(runs[k])) for k in keys]
    rows = [r for r in rows if math.isfinite(r[2])]
    if not rows:
        return []
    lines = [
        "",
        f"Why the crater does not converge: the hole the electrode drills (about its own "
        f"cross-section) deepens at a steady rate v, fitted over {DRILL_WINDOW_S[0]:g}-"
        f"{DRILL_WINDOW_S[1]:g} s, that rises with the resolution and does not move with dt:",
        "",
        "| run | fine mm | dt s | deepening rate mm/s | 1 / v s/mm |",
        "|---|---:|---:|---:|---:|",
    ]
    for k, h, v in rows:
        lines.append(
            f"| {k} | {h:g} | {float(runs[k]['dt_s']):g} | {v * 1e3:.2f} | {1e-3 / v:.3f} |"
        )
    base = [(h, v) for k, h, v in rows if float(runs[k]["dt_s"]) == DT_S]
    if len(base) >= 2:
        h = np.array([b[0] for b in base])
        inv = np.array([1e-3 / b[1] for b in base])
        B, A = np.polyfit(h, inv, 1)
        lines.append(
            f"\nFit over the dt {DT_S:g} s runs: 1 / v = {A:.3f} s/mm + {B:.3f} s/mm^2 x h "
            f"(h the fine spacing in mm): a delay per cell layer that shrinks as h^2, with a limit "
            f"of {1 / A:.1f} mm/s as h -> 0 if the fit holds below 0.2 mm; on it the default "
            f"0.4 mm drills at {100 * (A / (A + 0.4 * B)):.0f} % of that limit and 10 % needs "
            f"h <= {0.1 * A / (0.9 * B):.3f} mm."
        )
    return lines


def _variant_lines(runs: dict[str, dict[str, np.ndarray]], keys: list[str]) -> list[str]:
    """The model variants' runs beside the local-law, flat-contact run on the same grid, at
    every simulated time that the variants reached in common (the shortest run's end first),
    and the draped contact's own ladder against its finest run."""
    if not keys:
        return []
    ends = sorted({round(float(runs[k]["time_s"][-1]), 6) for k in keys})
    lines = [
        "",
        "Model variants against the shipped model on the same grid: the non-local cut driver "
        "(`level_set.nonlocal_length_m` = l; W averaged over l before it drives the front) and "
        "the draped contact (`electrodes[].contact` = draped: the disk follows the crater's "
        "surface under each of its points). Compared at each run's end that the others reach "
        "too; a run that stopped earlier (its wall limit) shows -.",
        "",
        "| grid | l mm | contact | t end s | first cut interp. s | "
        + " | ".join(f"cut {t:.2f} s mm^3 | depth {t:.2f} s mm | / shipped" for t in ends)
        + " | deepening rate mm/s |",
        "|---|---:|---|---:|---:|" + "---:|---:|---:|" * len(ends) + "---:|",
    ]
    for k in keys:
        d = runs[k]
        base = runs.get(f"fixed_{float(d['fine_mm']):g}mm")
        s = summary(d)
        cells = []
        for t in ends:
            if float(d["time_s"][-1]) < t - 1e-6:
                cells.append("- | - | -")
                continue
            cut = _at(d["time_s"], d["cut_m3"], t)
            ref = _at(base["time_s"], base["cut_m3"], t) if base is not None else math.nan
            cells.append(
                f"{_fmt(cut, 1e9)} | {_fmt(_at(d['time_s'], d['depth_m'], t), 1e3)} | "
                f"{_fmt(cut / ref if ref else math.nan, 1.0, 3)}"
            )
        lines.append(
            f"| {float(d['fine_mm']):g} mm | {_length_mm(d):g} | {_contact(d)} | "
            f"{float(d['time_s'][-1]):.2f} | {_fmt(s['cut_interp'], 1.0, 3)} | "
            + " | ".join(cells)
            + f" | {_fmt(drilling_rate(d), 1e3)} |"
        )
    return lines + _ladder_lines(runs, keys)


def _ladder_lines(runs: dict[str, dict[str, np.ndarray]], keys: list[str]) -> list[str]:
    """Each contact's coarser grids against its finest, at the time the finest draped run
    reached (the flat ladder at the same time, for comparison)."""
    draped = [k for k in keys if _contact(runs[k]) == "draped" and _length_mm(runs[k]) == 0.0]
    if len(draped) < 2:
        return []
    finest = min(draped, key=lambda k: float(runs[k]["fine_mm"]))
    t = float(runs[finest]["time_s"][-1])
    out = []
    for contact, ks in (("draped", draped), ("flat", [k.removesuffix("_draped") for k in draped])):
        ks = [k for k in ks if k in runs and float(runs[k]["time_s"][-1]) >= t - 1e-6]
        if len(ks) < 2:
            continue
        top = min(ks, key=lambda k: float(runs[k]["fine_mm"]))
        ref = _at(runs[top]["time_s"], runs[top]["cut_m3"], t)
        ref_d = _at(runs[top]["time_s"], runs[top]["depth_m"], t)
        parts = [
            f"{float(runs[k]['fine_mm']):g} mm {_at(runs[k]['time_s'], runs[k]['cut_m3'], t) / ref:.2f}"
            f" / {_at(runs[k]['time_s'], runs[k]['depth_m'], t) / ref_d:.2f}"
            for k in sorted(ks, key=lambda k: -float(runs[k]["fine_mm"]))
            if k != top
        ]
        out.append(
            f"- {contact} contact at t = {t:.2f} s, cut volume / depth against its "
            f"{float(runs[top]['fine_mm']):g} mm run: " + ", ".join(parts) + "."
        )
    return ["", *out] if out else []


def report() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = {
        p.stem.removeprefix("convergence_"): dict(np.load(p))
        for p in RESULTS.glob("convergence_*.npz")
    }
    local = [
        k
        for k in runs
        if k.startswith("fixed")
        and _length_mm(runs[k]) == 0.0
        and _contact(runs[k]) == "flat"
        and _surface_mm(runs[k]) == 0.0
    ]
    fixed = sorted(
        (k for k in local if float(runs[k]["dt_s"]) == DT_S),
        key=lambda k: -float(runs[k]["fine_mm"]) if float(runs[k]["fine_mm"]) > 0 else -1e9,
    )
    dt_runs = sorted(local, key=lambda k: (-float(runs[k]["fine_mm"]), -float(runs[k]["dt_s"])))
    variant_runs = sorted(
        (
            k
            for k in runs
            if k.startswith("fixed")
            and (_length_mm(runs[k]) > 0.0 or _contact(runs[k]) != "flat")
            and _surface_mm(runs[k]) == 0.0
        ),
        key=lambda k: (-float(runs[k]["fine_mm"]), _length_mm(runs[k])),
    )
    moving = sorted(k for k in runs if k.startswith("moving"))
    eq_w, ref_w = _ref_powers()
    sums = {k: summary(runs[k]) for k in runs}
    lines = [
        "# Grid convergence under the electrode (issue #21)",
        "",
        "`python benchmarks/convergence.py run --fine-mm F --seconds S` per row, `power`, "
        "`main-job`, then `report` (see the script's docstring). Fixed electrode: the "
        "`fixed-electrode` scene with a current-density drive (5.72e4 A/m^2 over the 1.17 mm "
        "disk, I = 0.246 A), all effects, dt 0.03 s, on its graded grid (fine cells over the "
        "contact + 2 mm, 12 mm deep, growth 1.25, cells <= 6.25 mm) with the fine spacing of the "
        "row; the shipped default is 0.4 mm. A run stops at its simulated target or its wall limit "
        "(t end). Shared 2-core machine, single-threaded BLAS: read step times as ratios.",
        "",
        f"Resolved-contact references: the issue's equipotential disk I^2 / (4 sigma a) = "
        f"{eq_w:.2f} W; this drive's limit (uniform current density, 8 I^2 / (3 pi^2 sigma a), "
        f"plus the block's own resistance by images) = {ref_w:.2f} W (`P / ref` uses it).",
        *_power_lines(ref_w),
        "",
        "Full runs. `step` columns: the first step at which T passes 100 C / the cut volume is "
        "positive (whole steps of dt); `interp.`: the time within the step at which T_max "
        "reaches 100 C / the largest nodal strain energy on the front reaches kappa (the cut "
        "criterion), linear between the two steps that bracket it.",
        "",
        "| grid | nodes | t end s | P W (step 1) | P / ref | 100 C step s | 100 C interp. s "
        "| first cut step s | first cut interp. s | cut 3 s mm^3 | depth 3 s mm | cut 6 s mm^3 "
        "| depth 6 s mm | peak p kPa | median step s | max RSS MiB |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for k in fixed:
        s = sums[k]
        lines.append(
            f"| {_grid_label(k, runs[k])} | {s['nodes']:.0f} | {s['t_end']:.2f} | "
            f"{s['power0']:.2f} | {s['power0'] / ref_w:.3f} | {_fmt(s['t100'])} | "
            f"{_fmt(s['t100_interp'], 1.0, 3)} | {_fmt(s['first_cut'])} | "
            f"{_fmt(s['cut_interp'], 1.0, 3)} | {_fmt(s['cut3'], 1e9)} | "
            f"{_fmt(s['depth3'], 1e3)} | {_fmt(s['cut6'], 1e9)} | {_fmt(s['depth6'], 1e3)} | "
            f"{s['p_peak'] / 1e3:.0f} | {s['step_median']:.2f} | {s['rss']:.0f} |"
        )
    graded = [k for k in fixed if float(runs[k]["fine_mm"]) > 0]
    ends = sorted({round(sums[k]["t_end"], 6) for k in graded})
    for tc in ends[:-1] if len(ends) > 1 else ends:  # each graded run's end, as far as others go
        here = [k for k in fixed if sums[k]["t_end"] >= tc - 1e-6]
        top = [k for k in graded if k in here][-1]
        fin = _at(runs[top]["time_s"], runs[top]["cut_m3"], tc)
        lines += [
            "",
            f"At t = {tc:.2f} s (the runs that reached it; 'finest' is {top}):",
            "",
            "| grid | cut mm^3 | depth mm | cut / finest |",
            "|---|---:|---:|---:|",
        ]
        for k in here:
            d = runs[k]
            cut, depth = _at(d["time_s"], d["cut_m3"], tc), _at(d["time_s"], d["depth_m"], tc)
            rel = cut / fin if fin else math.nan
            lines.append(
                f"| {k.removeprefix('fixed_')} | {_fmt(cut, 1e9)} | {_fmt(depth, 1e3)} | "
                f"{_fmt(rel, 1.0, 3)} |"
            )
    if graded:
        finest = sums[graded[-1]]
        lines += ["", f"Relative to the finest run ({graded[-1]}):", ""]
        lines += [
            "| grid | P | first cut (step) | first cut (interp.) | cut volume 3 s |",
            "|---|---:|---:|---:|---:|",
        ]
        for k in fixed:
            s = sums[k]
            rel = [
                s[q] / finest[q] - 1 if finest[q] and math.isfinite(finest[q]) else math.nan
                for q in ("power0", "first_cut", "cut_interp", "cut3")
            ]
            lines.append(
                f"| {k.removeprefix('fixed_')} | "
                + " | ".join(_fmt(v, 100, 1) + " %" for v in rel)
                + " |"
            )
    if len(graded) >= 3:
        a, b, c = (sums[k] for k in graded[-3:])
        lines += [
            "",
            f"Observed order over the three finest graded runs ({', '.join(graded[-3:])}): "
            f"P {observed_order(a['power0'], b['power0'], c['power0']):.2f}, first cut (interp.) "
            f"{observed_order(a['cut_interp'], b['cut_interp'], c['cut_interp']):.2f}, cut volume "
            f"at 3 s {observed_order(a['cut3'], b['cut3'], c['cut3']):.2f} (NaN: a value missing "
            "or equal).",
        ]
    studies = [k for k in dt_runs if float(runs[k]["dt_s"]) != DT_S]
    if studies:
        lines += [
            "",
            "Time step (same grid, dt halved): the step-resolved times move by whole steps, "
            "the interpolated ones by what the time discretisation itself changes:",
            "",
            "| run | dt s | 100 C step s | 100 C interp. s | first cut step s | first cut interp. s |",
            "|---|---:|---:|---:|---:|---:|",
        ]
        fines = {float(runs[k]["fine_mm"]) for k in studies}
        for k in dt_runs:
            if float(runs[k]["fine_mm"]) not in fines:
                continue
            s = sums[k]
            lines.append(
                f"| {k} | {float(runs[k]['dt_s']):g} | {_fmt(s['t100'], 1.0, 4)} | "
                f"{_fmt(s['t100_interp'], 1.0, 4)} | {_fmt(s['first_cut'], 1.0, 4)} | "
                f"{_fmt(s['cut_interp'], 1.0, 4)} |"
            )
    lines += _drilling_lines(runs, [k for k in dt_runs if float(runs[k]["fine_mm"]) > 0])
    lines += _probe_lines()
    lines += _variant_lines(runs, variant_runs)
    surfaced = [
        k
        for k in runs
        if k.startswith("fixed")
        and _surface_mm(runs[k]) > 0.0
        and _contact(runs[k]) == "flat"
        and _length_mm(runs[k]) == 0.0
        and float(runs[k]["dt_s"]) == DT_S
    ]
    lines += _surface_lines(runs, surfaced, fixed)
    lines += _cost_lines()
    if moving:
        lines += [
            "",
            "Moving electrode: the `moving-electrode` scene as shipped (50 W power drive, "
            "12.35 mm/s along the paper's path, all effects, its grid):",
            "",
            "| grid | nodes | t end s | first cut step s | first cut interp. s "
            "| cut at t end mm^3 | depth at t end mm | cut 6 s mm^3 | depth 6 s mm | cut 12 s mm^3 "
            "| depth 12 s mm | peak p kPa | median step s | max RSS MiB |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for k in moving:
            s = sums[k]
            lines.append(
                f"| {_grid_label(k, runs[k])} | {s['nodes']:.0f} | {s['t_end']:.2f} | "
                f"{_fmt(s['first_cut'])} | {_fmt(s['cut_interp'], 1.0, 3)} | "
                f"{_fmt(float(runs[k]['cut_m3'][-1]), 1e9)} | "
                f"{_fmt(float(runs[k]['depth_m'][-1]), 1e3)} | "
                f"{_fmt(s['cut6'], 1e9)} | {_fmt(s['depth6'], 1e3)} | {_fmt(s['cut12'], 1e9)} | "
                f"{_fmt(s['depth12'], 1e3)} | {s['p_peak'] / 1e3:.0f} | {s['step_median']:.2f} | "
                f"{s['rss']:.0f} |"
            )
    main = RESULTS / "convergence_main_job.json"
    if main.exists():
        jobs = json.loads(main.read_text())
        lines += [
            "",
            "The set-up's main job (`main-job`): the `default` scene (50 W, 3 s, all effects) on "
            "its grid and on the uniform 33x33x65, one after the other in one command, each in "
            "its own process:",
            "",
            "| grid | nodes | steps | first cut s | cut at end mm^3 | depth at end mm | median "
            "step s | p90 step s | cutting steps | median cutting step s | total s | max RSS MiB |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for j in jobs:
            lines.append(
                f"| {j['grid']}{' graded' if j['graded'] else ''} | {j['nodes']} | {j['steps']} | "
                f"{_fmt(j['first_cut_s'])} | {_fmt(j['cut_m3'], 1e9)} | "
                f"{_fmt(j['depth_m'], 1e3)} | {j['step_median_s']:.2f} | {j['step_p90_s']:.2f} | "
                f"{j.get('cutting_steps', '—')} | {j.get('cutting_median_s', math.nan):.2f} | "
                f"{j['total_s']:.0f} | {j['max_rss_mib']:.0f} |"
            )
        if len(jobs) == 2:
            u, g = jobs
            cut_ratio = g.get("cutting_median_s", math.nan) / u.get("cutting_median_s", math.nan)
            lines.append(
                f"\nGraded / uniform: median step {g['step_median_s'] / u['step_median_s']:.2f}x "
                f"(first cut at {u['first_cut_s']:.2f} s on the uniform grid against "
                f"{g['first_cut_s']:.2f} s: the runs cut for different shares of their steps), "
                "median cutting step "
                f"{cut_ratio:.2f}x, total {g['total_s'] / u['total_s']:.2f}x, max RSS "
                f"{g['max_rss_mib'] / u['max_rss_mib']:.2f}x."
            )
    (RESULTS / "convergence.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    fig, ax = plt.subplots(figsize=(7, 4))
    xs = np.linspace(-PROFILE_HALF_WIDTH_M, PROFILE_HALF_WIDTH_M, 201) * 1e3
    for k in fixed:
        d = runs[k]
        key = "profile_3s" if "profile_3s" in d else "profile_end"
        when = "3 s" if key == "profile_3s" else f"t = {float(d['time_s'][-1]):.2f} s"
        ax.plot(xs, -np.asarray(d[key]) * 1e3, label=f"{k.removeprefix('fixed_')} ({when})")
        if "profile_6s" in d:
            ax.plot(xs, -np.asarray(d["profile_6s"]) * 1e3, "--", label=f"{k} (6 s)")
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
    r.add_argument("--fine-mm", type=float, help="fine spacing; 0: uniform 33x33x65")
    r.add_argument("--moving", action="store_true", help="the moving-electrode scene, its grid")
    r.add_argument("--seconds", type=float, default=3.0)
    r.add_argument("--dt", type=float, default=DT_S, help="time step s (default 0.03)")
    r.add_argument("--wall-limit", type=float, default=3600.0)
    r.add_argument(
        "--length-mm", type=float, help="non-local length of the cut driver (default: the scene's)"
    )
    r.add_argument(
        "--contact", choices=("flat", "draped"), help="contact model (default: the scene's)"
    )
    r.add_argument(
        "--surface-mm",
        type=float,
        help="cell height at the top surface over the working region (default: the scene's; "
        "0: the fine spacing up to the surface)",
    )
    pw = sub.add_parser("power")
    pw.add_argument("--fine-mm", type=float, nargs="+", required=True)
    mj = sub.add_parser("main-job")
    mj.add_argument("--steps", type=int, default=100)
    pr = sub.add_parser("probe")
    pr.add_argument("--fine-mm", type=float, nargs="+", required=True)
    pr.add_argument("--steps", type=int, default=40)
    co = sub.add_parser("cost")
    co.add_argument("--fine-mm", type=float, default=0.4)
    co.add_argument("--surface-mm", type=float, default=0.1)
    co.add_argument("--warm", type=int, default=4)
    co.add_argument("--steps", type=int, default=10)
    sub.add_parser("report")
    a = ap.parse_args(argv)
    if a.cmd == "run":
        if a.fine_mm is None and not a.moving:
            ap.error("run: --fine-mm is required for the fixed electrode")
        fine = None if a.moving else a.fine_mm
        run(
            fine,
            moving=a.moving,
            seconds=a.seconds,
            wall_limit=a.wall_limit,
            dt_s=a.dt,
            length_mm=a.length_mm,
            contact=a.contact,
            surface_mm=a.surface_mm,
        )
    elif a.cmd == "cost":
        surface_cost(a.fine_mm, a.surface_mm, a.warm, a.steps)
    elif a.cmd == "power":
        power(a.fine_mm)
    elif a.cmd == "main-job":
        main_job(a.steps)
    elif a.cmd == "probe":
        for fine in a.fine_mm:
            floor_probe(fine, a.steps)
    else:
        report()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
