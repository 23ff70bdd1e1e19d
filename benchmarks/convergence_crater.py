"""The report's sections on why the fixed electrode's crater does not converge (issue #21):
the deepening rate per grid and its fit, the heating under the contact (``probe``), the model
variants (non-local driver, draped contact) and their ladders, the deeper reference region,
the Joule energy per removed volume, and the cell width against the cell height.

Each ``*_lines`` function takes the runs it compares (``convergence_runs``) and returns the
section's Markdown lines (none when it has nothing to show).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from convergence_runs import (
    DRILL_WINDOW_S,
    DT_S,
    REGION_DEPTH_MM,
    at,
    contact_model,
    drilling_rate,
    fine_z_mm,
    fmt,
    joule_energy,
    leaves_fine_region,
    length_mm,
    observed_order,
    region_mm,
    removal,
    summary,
)


def drilling_lines(runs: dict[str, dict[str, np.ndarray]], keys: list[str]) -> list[str]:
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
        hs = np.array([b[0] for b in base])
        inv = np.array([1e-3 / b[1] for b in base])
        B, A = np.polyfit(hs, inv, 1)
        lines.append(
            f"\nFit over the dt {DT_S:g} s runs: 1 / v = {A:.3f} s/mm + {B:.3f} s/mm^2 x h "
            f"(h the fine spacing in mm): a delay per cell layer that shrinks as h^2, with a limit "
            f"of {1 / A:.1f} mm/s as h -> 0 if the fit holds below 0.2 mm; on it the default "
            f"0.4 mm drills at {100 * (A / (A + 0.4 * B)):.0f} % of that limit and 10 % needs "
            f"h <= {0.1 * A / (0.9 * B):.3f} mm."
        )
    return lines


def probe_lines(results: Path) -> list[str]:
    """Floor-node heating rate and the power under the contact per probed grid (``probe``'s
    JSON in ``results``)."""
    path = results / "convergence_probe.json"
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
            f"{fmt(float(np.median([r.get('walls_1mm_w', math.nan) for r in tail])))} | "
            f"{np.median([r['power_w'] for r in tail]):.1f} | "
            f"{rec[0]['column_0_0.8mm_w']:.2f} | {rec[0]['power_w']:.1f} |"
        )
    return lines


def variant_lines(runs: dict[str, dict[str, np.ndarray]], keys: list[str]) -> list[str]:
    """The model variants' runs beside the local-law, flat-contact run on the same grid, at
    every simulated time that the variants reached in common (the shortest run's end first),
    and the draped contact's own ladder against its finest run."""
    if not keys:
        return []
    ends = sorted({round(float(runs[k]["time_s"][-1]), 6) for k in keys})
    lines = [
        "",
        "Model variants against the shipped model on the same grid: the non-local cut driver "
        "(`level_set.nonlocal_length_m` = l; W averaged over l before it drives the front), "
        "the draped contact (`electrodes[].contact` = draped: the disk follows the crater's "
        "surface under each of its points) and the removal by fraction "
        "(`level_set.removal` = fraction: a partly cut tet's properties blend by the tissue "
        "left in it). Compared at each run's end that the others reach "
        "too; a run that stopped earlier (its wall limit) shows -.",
        "",
        "| grid | l mm | contact | removal | t end s | first cut interp. s | "
        + " | ".join(f"cut {t:.2f} s mm^3 | depth {t:.2f} s mm | / shipped" for t in ends)
        + " | deepening rate mm/s |",
        "|---|---:|---|---|---:|---:|" + "---:|---:|---:|" * len(ends) + "---:|",
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
            cut = at(d["time_s"], d["cut_m3"], t)
            ref = at(base["time_s"], base["cut_m3"], t) if base is not None else math.nan
            cells.append(
                f"{fmt(cut, 1e9)} | {fmt(at(d['time_s'], d['depth_m'], t), 1e3)} | "
                f"{fmt(cut / ref if ref else math.nan, 1.0, 3)}"
            )
        lines.append(
            f"| {float(d['fine_mm']):g} mm | {length_mm(d):g} | {contact_model(d)} | "
            f"{removal(d)} | "
            f"{float(d['time_s'][-1]):.2f} | {fmt(s['cut_interp'], 1.0, 3)} | "
            + " | ".join(cells)
            + f" | {fmt(drilling_rate(d), 1e3)} |"
        )
    return lines + ladder_lines(runs, keys)


def ladder_lines(runs: dict[str, dict[str, np.ndarray]], keys: list[str]) -> list[str]:
    """Each contact's coarser grids against its finest, at the time the finest draped run
    reached (the flat ladder at the same time, for comparison)."""
    draped = [k for k in keys if contact_model(runs[k]) == "draped" and length_mm(runs[k]) == 0.0]
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
        ref = at(runs[top]["time_s"], runs[top]["cut_m3"], t)
        ref_d = at(runs[top]["time_s"], runs[top]["depth_m"], t)
        parts = [
            f"{float(runs[k]['fine_mm']):g} mm {at(runs[k]['time_s'], runs[k]['cut_m3'], t) / ref:.2f}"
            f" / {at(runs[k]['time_s'], runs[k]['depth_m'], t) / ref_d:.2f}"
            for k in sorted(ks, key=lambda k: -float(runs[k]["fine_mm"]))
            if k != top
        ]
        out.append(
            f"- {contact} contact at t = {t:.2f} s, cut volume / depth against its "
            f"{float(runs[top]['fine_mm']):g} mm run: " + ", ".join(parts) + "."
        )
    return ["", *out] if out else []


def depth_lines(runs: dict[str, dict[str, np.ndarray]], deeper: list[str]) -> list[str]:
    """Each run made with a deeper working region (``run --depth-mm``) beside its twin at the
    scene's depth: the crater at 1.62 / 2.4 / 3 s, and the 0.4 mm runs' ratio against each."""
    if not deeper:
        return []
    lines = [
        "",
        f"The reference's region (`run --depth-mm`): a run made with a deeper working region "
        f"beside the same run at the scene's {REGION_DEPTH_MM:g} mm, so that its crater stays in "
        f"fine cells; the 0.4 mm rows' crater / this run's.",
        "",
        "| run | region mm | nodes | t end s | crater leaves s | cut 1.62 s mm^3 | cut 2.4 s mm^3 "
        "| cut 3 s mm^3 | depth 3 s mm | 0.4 mm / it at 3 s | 0.4 mm (s0.1) / it at 3 s |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for k in deeper:
        twin = k.rsplit("_d", 1)[0]
        for kk in (twin, k):
            if kk not in runs:
                continue
            d = runs[kk]
            t, cut = d["time_s"], d["cut_m3"]
            c3 = at(t, cut, 3.0)
            ratios = [
                fmt(at(runs[r]["time_s"], runs[r]["cut_m3"], 3.0) / c3, 1.0, 3)
                if r in runs and c3
                else "—"
                for r in ("fixed_0.4mm", "fixed_0.4mm_s0.1")
            ]
            lines.append(
                f"| {kk} | {region_mm(d):g} | {int(d['n_nodes'])} | {float(t[-1]):.2f} | "
                f"{fmt(leaves_fine_region(d))} | {fmt(at(t, cut, 1.62), 1e9)} | "
                f"{fmt(at(t, cut, 2.4), 1e9)} | {fmt(c3, 1e9)} | "
                f"{fmt(at(t, d['depth_m'], 3.0), 1e3)} | {ratios[0]} | {ratios[1]} |"
            )
    return lines


ENERGY_TIMES_S = (1.62, 3.0)
"""Simulated times at which the Joule energy per removed volume is compared."""


def energy_lines(runs: dict[str, dict[str, np.ndarray]], keys: list[str]) -> list[str]:
    """The Joule energy per removed volume at ``ENERGY_TIMES_S`` per graded run (those of
    ``keys`` that reached the time), with the fit a + b h over the fine spacings h."""
    lines = [
        "",
        "Energy per removed volume: the Joule energy delivered by t over the crater's volume at t. "
        "What is not in the removed tissue heats the tissue that stays, and the grid gives the "
        "crater's heated skin at least a cell's thickness, so this ratio carries the crater's "
        "dependence on the grid (docs/resolution.md: it follows the lateral spacing, not the "
        "vertical one). Fit a + b h by least squares over the runs at each time (h in mm); the "
        "order over three spacings where there are three.",
        "",
        "| t s | run | fine mm | region mm | energy J | cut mm^3 | J/mm^3 |",
        "|---:|---|---:|---:|---:|---:|---:|",
    ]
    fits = []
    for t in ENERGY_TIMES_S:
        rows = []
        for k in keys:
            d = runs[k]
            if float(d["time_s"][-1]) < t - 1e-6:
                continue
            cut = at(d["time_s"], d["cut_m3"], t) * 1e9
            if not cut > 0:
                continue
            e = joule_energy(d, t)
            rows.append((float(d["fine_mm"]), e / cut))
            lines.append(
                f"| {t:g} | {k} | {float(d['fine_mm']):g} | {region_mm(d):g} | {e:.1f} | "
                f"{cut:.1f} | {e / cut:.3f} |"
            )
        hs = sorted({h for h, _ in rows}, reverse=True)
        if len(hs) >= 2:
            b, a = np.polyfit([h for h, _ in rows], [r for _, r in rows], 1)
            by_h = {h: float(np.mean([r for hh, r in rows if hh == h])) for h in hs}
            order = observed_order(*(by_h[h] for h in hs[:3])) if len(hs) >= 3 else math.nan
            fits.append(
                f"- t = {t:g} s: J/mm^3 = {a:.3f} + {b:.3f} h (h -> 0: {a:.3f}; b / a = "
                f"{b / a:.2f} per mm), observed order {fmt(order)}; at the fit the 0.4 mm grid "
                f"removes {100 * a / (a + 0.4 * b):.0f} % and the 0.2 mm grid "
                f"{100 * a / (a + 0.2 * b):.0f} % of the volume per joule of h -> 0."
            )
    return lines + (["", *fits] if fits else [])


def axis_lines(runs: dict[str, dict[str, np.ndarray]], keys: list[str]) -> list[str]:
    """The runs whose working region has a cell height of its own (``run --fine-z-mm``) beside
    the cubic runs of the same width, at the time they all reached."""
    if not keys:
        return []
    widths = sorted({float(runs[k]["fine_mm"]) for k in keys}, reverse=True)
    rows = [
        k
        for k in runs
        if k.startswith("fixed")
        and float(runs[k]["fine_mm"]) in widths
        and (k in keys or k == f"fixed_{float(runs[k]['fine_mm']):g}mm")
    ]
    t = min(float(runs[k]["time_s"][-1]) for k in rows)
    lines = [
        "",
        f"Cell width against cell height (`run --fine-mm W --fine-z-mm H`: the working region's "
        f"cells W wide and H tall), at t = {t:.2f} s: the crater's volume follows the width, its "
        f"depth and the first cut the height.",
        "",
        "| run | width mm | height mm | nodes | first cut interp. s | cut mm^3 | depth mm "
        "| cut / depth mm^2 | J/mm^3 | median step s |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for k in sorted(rows, key=lambda k: (-float(runs[k]["fine_mm"]), -fine_z_mm(runs[k]))):
        d = runs[k]
        cut, depth = at(d["time_s"], d["cut_m3"], t), at(d["time_s"], d["depth_m"], t)
        lines.append(
            f"| {k} | {float(d['fine_mm']):g} | {fine_z_mm(d):g} | {int(d['n_nodes'])} | "
            f"{fmt(summary(d)['cut_interp'], 1.0, 3)} | {fmt(cut, 1e9)} | "
            f"{fmt(depth, 1e3)} | {fmt(cut / depth if depth else math.nan, 1e6)} | "
            f"{fmt(joule_energy(d, t) / (cut * 1e9) if cut else math.nan, 1.0, 3)} | "
            f"{float(np.median(d['wall_s'])):.2f} |"
        )
    return lines
