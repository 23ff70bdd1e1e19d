"""The tables and plot of ``convergence.py report``: every saved run read back and summed up.

``report`` reads every run that ``convergence.py run`` saved (``convergence_*.npz`` in
``benchmarks/results``) and the JSON that ``power``, ``probe``, ``main-job`` and ``cost`` wrote
beside them, and writes ``convergence.md`` (the fixed electrode's ladder of graded grids and the
uniform 33x33x65, the step-1 power ladder, the dt study, the surface-refined ladder and its cost
per step, the moving electrode, the default scene's main job, and the sections on why the
crater does not converge, ``convergence_crater``) and ``convergence.png`` (the crater profile
per resolution). What a run's figures are: ``convergence_runs``.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
from convergence_crater import (
    axis_lines,
    depth_lines,
    drilling_lines,
    energy_lines,
    probe_lines,
    variant_lines,
)
from convergence_runs import (
    DT_S,
    PROFILE_HALF_WIDTH_M,
    REGION_DEPTH_MM,
    RESULTS,
    ROOT,
    at,
    contact_model,
    cubic,
    fmt,
    grid_label,
    length_mm,
    observed_order,
    removal,
    standard_depth,
    summary,
    surface_mm,
)

sys.path.insert(0, str(ROOT / "server"))

from diathermy.physics.contact_resistance import (  # noqa: E402
    block_image_resistance,
    equipotential_disk_resistance,
    uniform_flux_disk_resistance,
)

__all__ = ["DT_S", "PROFILE_HALF_WIDTH_M", "REGION_DEPTH_MM", "RESULTS", "report"]

Runs = dict[str, dict[str, np.ndarray]]


def _ref_powers() -> tuple[float, float]:
    """The resolved-contact powers in W: the equipotential disk's, and this drive's (uniform
    current density plus the block's own resistance)."""
    current = 5.72e4 * math.pi * 1.17e-3**2
    eq_w = current**2 * equipotential_disk_resistance(0.33, 1.17e-3)
    ref_w = current**2 * (
        uniform_flux_disk_resistance(0.33, 1.17e-3)
        + block_image_resistance(0.33, (0.2, 0.1, 0.1), (0.0, 0.0, 0.0), (0.1, 0.05))
    )
    return eq_w, ref_w


def _power_lines(ref_w: float, results: Path) -> list[str]:
    """The step-1 power ladder (``power``'s JSON in ``results``) and its observed orders."""
    path = results / "convergence_power.json"
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


def _cost_lines(results: Path) -> list[str]:
    """What the surface refinement costs a step (each of ``cost``'s JSONs in ``results``)."""
    lines: list[str] = []
    for path in sorted(results.glob("convergence_surface_cost*.json")):
        lines += _cost_table(json.loads(path.read_text()))
    return lines


def _cost_table(c: dict) -> list[str]:
    """One ``cost`` run: the plain and the surface-refined grid side by side."""
    p, r = c["runs"]["plain"], c["runs"]["surface"]
    effs = sorted(set(p["effects_median_s"]) | set(r["effects_median_s"]))
    deep = c.get("deep_mm")
    lines = [
        "",
        f"What the surface refinement costs (`cost --fine-mm {c['fine_mm']:g} --surface-mm "
        f"{r['surface_mm']:g}{f' --deep-mm {deep:g}' if deep else ''}`"
        f"{f', both grids with the deep tier to {deep:g} mm' if deep else ''}): both grids in "
        f"one process, {c['warm']} steps each past the first cut, then {c['steps']} steps each, "
        "alternating (incremental default):",
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
        + " | crater leaves the fine region s |",
        "|---|---:|---:|---:|---:|---:|" + "---:|---:|" * len(times) + "---:|",
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
                cut = at(d["time_s"], d["cut_m3"], t)
                ref = at(runs[top]["time_s"], runs[top]["cut_m3"], t)
                cells.append(f"{fmt(cut, 1e9)} | {fmt(cut / ref if ref else math.nan, 1.0, 3)}")
            lines.append(
                f"| {float(d['fine_mm']):g} mm | {surface_mm(d):g} | {int(d['n_nodes'])} | "
                f"{fmt(s_['t100_interp'], 1.0, 4)} | {fmt(s_['cut_interp'], 1.0, 4)} | "
                f"{fmt(s_['cut_interp'] / fin['cut_interp'], 1.0, 3)} | "
                + " | ".join(cells)
                + f" | {fmt(s_['leaves'])} |"
            )
    if math.isfinite(fin["leaves"]):
        lines.append(
            f"\nThe crater's floor passes the working region's depth ({float(runs[top]['depth_mm']):g}"
            f" mm) at the time in the last column and digs on in cells that grow by the growth "
            f"ratio: from then on a run is no longer at its fine spacing, the finest refined run "
            f"from {fin['leaves']:.2f} s. Its later figures are a lower bound on a run fine all "
            f"the way down (coarser cells drill slower, above)."
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


def _ladder_lines(
    runs: Runs, fixed: list[str], sums: dict[str, dict[str, float]], ref_w: float
) -> list[str]:
    """The fixed electrode's full runs, their crater at each graded run's end, each against the
    finest graded run, and the observed orders over the three finest."""
    lines = [
        "",
        "Full runs. `step` columns: the first step at which T passes 100 C / the cut volume is "
        "positive (whole steps of dt); `interp.`: the time within the step at which T_max "
        "reaches 100 C / the largest nodal strain energy on the front reaches kappa (the cut "
        "criterion), linear between the two steps that bracket it.",
        "",
        "| grid | nodes | t end s | P W (step 1) | P / ref | 100 C step s | 100 C interp. s "
        "| first cut step s | first cut interp. s | cut 3 s mm^3 | depth 3 s mm | cut 6 s mm^3 "
        "| depth 6 s mm | crater leaves the fine region s | peak p kPa | median step s "
        "| max RSS MiB |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for k in fixed:
        s = sums[k]
        lines.append(
            f"| {grid_label(k, runs[k])} | {s['nodes']:.0f} | {s['t_end']:.2f} | "
            f"{s['power0']:.2f} | {s['power0'] / ref_w:.3f} | {fmt(s['t100'])} | "
            f"{fmt(s['t100_interp'], 1.0, 3)} | {fmt(s['first_cut'])} | "
            f"{fmt(s['cut_interp'], 1.0, 3)} | {fmt(s['cut3'], 1e9)} | "
            f"{fmt(s['depth3'], 1e3)} | {fmt(s['cut6'], 1e9)} | {fmt(s['depth6'], 1e3)} | "
            f"{fmt(s['leaves'])} | {s['p_peak'] / 1e3:.0f} | {s['step_median']:.2f} | "
            f"{s['rss']:.0f} |"
        )
    graded = [k for k in fixed if float(runs[k]["fine_mm"]) > 0]
    ends = sorted({round(sums[k]["t_end"], 6) for k in graded})
    for tc in ends[:-1] if len(ends) > 1 else ends:  # each graded run's end, as far as others go
        here = [k for k in fixed if sums[k]["t_end"] >= tc - 1e-6]
        top = [k for k in graded if k in here][-1]
        fin = at(runs[top]["time_s"], runs[top]["cut_m3"], tc)
        lines += [
            "",
            f"At t = {tc:.2f} s (the runs that reached it; 'finest' is {top}):",
            "",
            "| grid | cut mm^3 | depth mm | cut / finest |",
            "|---|---:|---:|---:|",
        ]
        for k in here:
            d = runs[k]
            cut, depth = at(d["time_s"], d["cut_m3"], tc), at(d["time_s"], d["depth_m"], tc)
            rel = cut / fin if fin else math.nan
            lines.append(
                f"| {k.removeprefix('fixed_')} | {fmt(cut, 1e9)} | {fmt(depth, 1e3)} | "
                f"{fmt(rel, 1.0, 3)} |"
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
            rels = [
                s[q] / finest[q] - 1 if finest[q] and math.isfinite(finest[q]) else math.nan
                for q in ("power0", "first_cut", "cut_interp", "cut3")
            ]
            lines.append(
                f"| {k.removeprefix('fixed_')} | "
                + " | ".join(fmt(v, 100, 1) + " %" for v in rels)
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
    return lines


def _dt_lines(runs: Runs, dt_runs: list[str], sums: dict[str, dict[str, float]]) -> list[str]:
    """The runs with another time step beside the default-dt run on the same grid."""
    studies = [k for k in dt_runs if float(runs[k]["dt_s"]) != DT_S]
    if not studies:
        return []
    lines = [
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
            f"| {k} | {float(runs[k]['dt_s']):g} | {fmt(s['t100'], 1.0, 4)} | "
            f"{fmt(s['t100_interp'], 1.0, 4)} | {fmt(s['first_cut'], 1.0, 4)} | "
            f"{fmt(s['cut_interp'], 1.0, 4)} |"
        )
    return lines


def _moving_lines(runs: Runs, moving: list[str], sums: dict[str, dict[str, float]]) -> list[str]:
    """The moving electrode's runs: first cut, and the cut along the path at 6 and 12 s."""
    if not moving:
        return []
    lines = [
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
            f"| {grid_label(k, runs[k])} | {s['nodes']:.0f} | {s['t_end']:.2f} | "
            f"{fmt(s['first_cut'])} | {fmt(s['cut_interp'], 1.0, 3)} | "
            f"{fmt(float(runs[k]['cut_m3'][-1]), 1e9)} | "
            f"{fmt(float(runs[k]['depth_m'][-1]), 1e3)} | "
            f"{fmt(s['cut6'], 1e9)} | {fmt(s['depth6'], 1e3)} | {fmt(s['cut12'], 1e9)} | "
            f"{fmt(s['depth12'], 1e3)} | {s['p_peak'] / 1e3:.0f} | {s['step_median']:.2f} | "
            f"{s['rss']:.0f} |"
        )
    return lines


def _main_job_lines(results: Path) -> list[str]:
    """The default scene's main job on its grid and on 33x33x65 (``main-job``'s JSON in
    ``results``) and their ratios."""
    main = results / "convergence_main_job.json"
    if not main.exists():
        return []
    jobs = json.loads(main.read_text())
    lines = [
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
            f"{fmt(j['first_cut_s'])} | {fmt(j['cut_m3'], 1e9)} | "
            f"{fmt(j['depth_m'], 1e3)} | {j['step_median_s']:.2f} | {j['step_p90_s']:.2f} | "
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
    with_effects = [j for j in jobs if j.get("cutting_effects_median_s")]
    if with_effects:
        effs = sorted({e for j in with_effects for e in j["cutting_effects_median_s"]})
        lines += [
            "",
            "Median time of each effect over the cutting steps (s; 0 on a step it skipped):",
            "",
            "| grid | " + " | ".join(effs) + " |",
            "|---|" + "---:|" * len(effs),
        ]
        for j in with_effects:
            med = j["cutting_effects_median_s"]
            lines.append(
                f"| {j['grid']}{' graded' if j['graded'] else ''} | "
                + " | ".join(f"{med.get(e, 0.0):.3f}" for e in effs)
                + " |"
            )
    return lines


def _plot(runs: Runs, fixed: list[str], path: Path) -> None:
    """The crater profile through the contact per fixed-electrode run, at 3 s (and 6 s) or at
    the run's end, to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

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
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report() -> None:
    """``convergence.md`` and ``convergence.png`` in ``RESULTS`` from every run and JSON there;
    the table is printed too."""
    every = {
        p.stem.removeprefix("convergence_"): dict(np.load(p))
        for p in RESULTS.glob("convergence_*.npz")
    }
    deeper = sorted(k for k, d in every.items() if k.startswith("fixed") and not standard_depth(d))
    tall = sorted(k for k, d in every.items() if k.startswith("fixed") and not cubic(d))
    runs = {k: d for k, d in every.items() if k not in deeper and k not in tall}
    local = [
        k
        for k in runs
        if k.startswith("fixed")
        and length_mm(runs[k]) == 0.0
        and contact_model(runs[k]) == "flat"
        and removal(runs[k]) == "threshold"
        and surface_mm(runs[k]) == 0.0
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
            and (
                length_mm(runs[k]) > 0.0
                or contact_model(runs[k]) != "flat"
                or removal(runs[k]) != "threshold"
            )
            and surface_mm(runs[k]) == 0.0
        ),
        key=lambda k: (-float(runs[k]["fine_mm"]), length_mm(runs[k])),
    )
    surfaced = [
        k
        for k in runs
        if k.startswith("fixed")
        and surface_mm(runs[k]) > 0.0
        and contact_model(runs[k]) == "flat"
        and length_mm(runs[k]) == 0.0
        and removal(runs[k]) == "threshold"
        and float(runs[k]["dt_s"]) == DT_S
    ]
    moving = sorted(k for k in runs if k.startswith("moving"))
    graded = [k for k in fixed if float(runs[k]["fine_mm"]) > 0]
    eq_w, ref_w = _ref_powers()
    sums = {k: summary(runs[k]) for k in runs}
    lines = [
        "# Grid convergence under the electrode (issue #21)",
        "",
        "`python benchmarks/convergence.py run --fine-mm F --seconds S` per row, `power`, "
        "`main-job`, then `report` (see the script's docstring). Fixed electrode: the "
        "`fixed-electrode` scene with a current-density drive (5.72e4 A/m^2 over the 1.17 mm "
        "disk, I = 0.246 A), all effects, dt 0.03 s, on its graded grid (fine cells over the "
        f"contact + 2 mm, {REGION_DEPTH_MM:g} mm deep, growth 1.25, cells <= 6.25 mm) with the "
        "fine spacing of the row; the shipped default is 0.4 mm. A run stops at its simulated "
        "target or its wall limit (t end). Shared 2-core machine, single-threaded BLAS: read "
        "step times as ratios.",
        "",
        f"Resolved-contact references: the issue's equipotential disk I^2 / (4 sigma a) = "
        f"{eq_w:.2f} W; this drive's limit (uniform current density, 8 I^2 / (3 pi^2 sigma a), "
        f"plus the block's own resistance by images) = {ref_w:.2f} W (`P / ref` uses it).",
        *_power_lines(ref_w, RESULTS),
        *_ladder_lines(runs, fixed, sums, ref_w),
        *_dt_lines(runs, dt_runs, sums),
        *drilling_lines(runs, [k for k in dt_runs if float(runs[k]["fine_mm"]) > 0]),
        *probe_lines(RESULTS),
        *variant_lines(runs, variant_runs),
        *_surface_lines(runs, surfaced, fixed),
        *depth_lines(every, deeper),
        *energy_lines(every, graded + deeper),
        *axis_lines(every, tall),
        *_cost_lines(RESULTS),
        *_moving_lines(runs, moving, sums),
        *_main_job_lines(RESULTS),
    ]
    (RESULTS / "convergence.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    _plot(runs, fixed, RESULTS / "convergence.png")
    print((RESULTS / "convergence.md").read_text())
