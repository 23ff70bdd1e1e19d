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
    python benchmarks/convergence.py cost --fine-mm 0.4 --surface-mm 0.1 [--deep-mm 90]  # its cost
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
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "server"))
sys.path.insert(0, str(ROOT / "benchmarks"))

# the tables and plot of ``report`` live in convergence_report.py
from convergence_report import (  # noqa: E402
    DT_S,
    PROFILE_HALF_WIDTH_M,
    REGION_DEPTH_MM,
    RESULTS,
    report,
)

from diathermy.engine.removal import tissue_share  # noqa: E402
from diathermy.engine.simulation import Simulation  # noqa: E402
from diathermy.physics.dissection import cut_driver  # noqa: E402
from diathermy.physics.topology import contact_height  # noqa: E402
from diathermy.runtime import own_peak_rss_mib  # noqa: E402
from diathermy.scene import Scene, builtin_scene  # noqa: E402

PROFILE_TIMES_S = (3.0, 6.0, 12.0)
"""Simulated times at which the crater profile is saved."""


UNIFORM = (33, 33, 65)


def scene_for(
    fine_mm: float | None,
    *,
    moving: bool,
    dt_s: float = DT_S,
    length_mm: float | None = None,
    contact: str | None = None,
    surface_mm: float | None = None,
    depth_mm: float | None = None,
    fine_z_mm: float | None = None,
    deep_mm: float | None = None,
    removal: str | None = None,
) -> Scene:
    """The fixed electrode (current-density drive) with its resolution at ``fine_mm`` (0: uniform
    33x33x65), or the moving electrode as shipped (``fine_mm`` None: its own grid); the cut
    driver's non-local length at ``length_mm``, the electrode's contact model at ``contact``,
    the cell height at the top surface at ``surface_mm`` (None or 0: fine_mm up to the surface,
    whatever the fixed scene ships), the
    working region's depth at ``depth_mm`` (None: the scene's), its cell height at
    ``fine_z_mm`` (None: fine_mm), a deep tier under it to ``deep_mm`` (None: none, whatever
    the scene ships, so that the recorded ladder keeps its grids) and the cut's
    ``level_set.removal`` (None: the scene's)."""
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
    if removal is not None:
        base["level_set"] = {**base["level_set"], "removal": removal}
    if not moving and base.get("resolution") is not None:  # none unless given, as deep_mm
        surface = surface_mm * 1e-3 if surface_mm else None
        base["resolution"] = {**base["resolution"], "surface_m": surface}
    if depth_mm is not None and base.get("resolution") is not None:
        base["resolution"] = {**base["resolution"], "depth_m": depth_mm * 1e-3}
    if fine_z_mm is not None and base.get("resolution") is not None:
        base["resolution"] = {**base["resolution"], "fine_z_m": fine_z_mm * 1e-3}
    if not moving and base.get("resolution") is not None:
        deep = deep_mm * 1e-3 if deep_mm else None
        base["resolution"] = {**base["resolution"], "deep_m": deep}
    return Scene.model_validate(base)


def tag_of(
    fine_mm: float | None,
    moving: bool,
    dt_s: float = DT_S,
    length_mm: float = 0.0,
    contact: str = "flat",
    surface_mm: float = 0.0,
    depth_mm: float = REGION_DEPTH_MM,
    fine_z_mm: float | None = None,
    deep_mm: float | None = None,
    removal: str = "threshold",
) -> str:
    """The run's file tag: scene, grid, dt if not the default, the non-local length if any, the
    contact model if not flat, the surface cell if refined, the region's depth if not 12 mm, the
    region's cell height if not the fine spacing, the deep tier's depth if any, the removal rule
    if not the threshold."""
    kind = "moving" if moving else "fixed"
    grid = "default" if fine_mm is None else "uniform" if fine_mm <= 0 else f"{fine_mm:g}mm"
    tag = f"{kind}_{grid}" + ("" if dt_s == DT_S else f"_dt{dt_s:g}")
    tag += f"_l{length_mm:g}" if length_mm > 0 else ""
    tag += "" if contact == "flat" else f"_{contact}"
    tag += f"_s{surface_mm:g}" if surface_mm > 0 else ""
    tag += "" if depth_mm in (0.0, REGION_DEPTH_MM) else f"_d{depth_mm:g}"
    tag += "" if fine_z_mm is None or fine_z_mm == fine_mm else f"_z{fine_z_mm:g}"
    tag += f"_deep{deep_mm:g}" if deep_mm else ""
    return tag + ("" if removal == "threshold" else f"_{removal}")


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
        tissue_share=tissue_share(sim.ctx, sim.state),
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
    depth_mm: float | None = None,
    fine_z_mm: float | None = None,
    deep_mm: float | None = None,
    removal: str | None = None,
) -> Path:
    scene = scene_for(
        fine_mm, moving=moving, dt_s=dt_s, length_mm=length_mm, contact=contact,
        surface_mm=surface_mm, depth_mm=depth_mm, fine_z_mm=fine_z_mm, deep_mm=deep_mm,
        removal=removal,
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
    tag = tag_of(
        fine_mm, moving, dt_s, length_mm, contact, surface_mm,
        REGION_DEPTH_MM if depth_mm is None else depth_mm, fine_z_mm, deep_mm,
        scene.level_set.removal,
    )  # fmt: skip
    out = RESULTS / f"convergence_{tag}.npz"
    arrays: dict[str, Any] = {**{k: np.asarray(v) for k, v in rec.items()}, **profiles}
    np.savez(
        out,
        **arrays,
        fine_mm=res.fine_m * 1e3 if res is not None else 0.0,
        fine_z_mm=res.fine_spacing_m[2] * 1e3 if res is not None else 0.0,
        depth_mm=res.depth_m * 1e3 if res is not None else 0.0,
        deep_mm=res.deep_m * 1e3 if res is not None and res.deep_m is not None else 0.0,
        dt_s=scene.dt_s,
        kappa=sim.tissue.damage_kappa_j_per_m3,
        moving=moving,
        shape=np.asarray(sim.grid.shape),
        n_nodes=sim.grid.n_nodes,
        build_s=build_s,
        max_rss_mib=own_peak_rss_mib(),
        target_s=seconds,
        length_mm=length_mm,
        contact=contact,
        surface_mm=surface_mm,
        removal=scene.level_set.removal,
    )
    print(f"{out.name}: {len(rec['time_s'])} steps to t = {rec['time_s'][-1]:.2f} s")
    return out


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
    effects: dict[str, list[float]] = {}
    for _ in range(steps):
        r = sim.step()
        walls.append(r.wall_s)
        if math.isfinite(cut_at):
            cutting.append(r.wall_s)  # the steps after the first cut: like with like
            for eff, er in r.effects.items():
                effects.setdefault(eff, []).append(er.wall_s if er.ran else 0.0)
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
        "cutting_effects_median_s": {e: float(np.median(v)) for e, v in effects.items()},
        "first_cut_s": cut_at,
        "cut_m3": r.cut_volume_m3,
        "depth_m": r.crater_depth_m,
        "max_rss_mib": own_peak_rss_mib(),
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


def surface_cost(
    fine_mm: float, surface_mm: float, warm: int, steps: int, deep_mm: float | None = None
) -> Path:
    """What the surface refinement costs a step: the fixed electrode (current-density drive,
    the incremental default) on the plain grid of ``fine_mm`` and on the one refined to
    ``surface_mm`` at the top (both with a deep tier to ``deep_mm`` when given), ``warm`` steps
    each (past the first cut), then ``steps`` steps each, alternating, so the shared machine's
    load falls on both alike."""
    sims = {
        name: Simulation(scene_for(fine_mm, moving=False, surface_mm=surface, deep_mm=deep_mm))
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
    out = RESULTS / f"convergence_surface_cost{f'_deep{deep_mm:g}' if deep_mm else ''}.json"
    out.write_text(
        json.dumps(
            {"fine_mm": fine_mm, "deep_mm": deep_mm, "warm": warm, "steps": steps, "runs": rows},
            indent=1,
        ),
        encoding="utf-8",
    )
    print(f"{out.name}: median {rows['surface']['median_s'] / rows['plain']['median_s']:.2f}x")
    return out


def main(argv: list[str] | None = None) -> int:
    from diathermy.runtime import configure_threads

    configure_threads()  # as the CLI and the server run: one BLAS thread
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
    r.add_argument(
        "--depth-mm",
        type=float,
        help=f"the working region's depth (default: the scene's, {REGION_DEPTH_MM:g} mm)",
    )
    r.add_argument(
        "--fine-z-mm",
        type=float,
        help="the working region's cell height (default: the fine spacing)",
    )
    r.add_argument(
        "--deep-mm",
        type=float,
        help="a deep tier under the working region down to this depth (resolution.deep_m; "
        "default: none, whatever the scene ships)",
    )
    r.add_argument(
        "--removal",
        choices=("threshold", "fraction"),
        help="the cut's level_set.removal (default: the scene's)",
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
    co.add_argument("--deep-mm", type=float, help="both grids with a deep tier to this depth")
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
            depth_mm=a.depth_mm,
            fine_z_mm=a.fine_z_mm,
            deep_mm=a.deep_mm,
            removal=a.removal,
        )
    elif a.cmd == "cost":
        surface_cost(a.fine_mm, a.surface_mm, a.warm, a.steps, a.deep_mm)
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
