"""The tables and plot of ``convergence.py report``: every saved run read back and summed up.

``report`` reads every run that ``convergence.py run`` saved (``convergence_*.npz`` in
``benchmarks/results``) and the JSON that ``power``, ``probe``, ``main-job`` and ``cost`` wrote
beside them, and writes ``convergence.md`` (the fixed electrode's ladder of graded grids and the
uniform 33x33x65, the step-1 power ladder, the dt study, the deepening rate per grid, the heating
under the contact, the model variants, the surface-refined ladder and its cost per step, the
moving electrode, the default scene's main job) and ``convergence.png`` (the crater profile per
resolution). Beside it what the tables rest on: ``summary`` (per run: the times to 100 C and to
the first cut, per step and within it by ``crossing``, the crater at 3 / 6 / 12 s, peak
pressure, power, step time, memory), ``observed_order`` and ``drilling_rate``.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "server"))

from diathermy.physics.contact_resistance import (  # noqa: E402
    block_image_resistance,
    equipotential_disk_resistance,
    uniform_flux_disk_resistance,
)

RESULTS = ROOT / "benchmarks" / "results"
"""Where ``convergence.py`` saves its runs and ``report`` reads them and writes its table."""
PROFILE_HALF_WIDTH_M = 6e-3
"""Half the width of a saved crater profile (201 points along x through the contact)."""
T_BOIL_K = 373.15
T_INITIAL_K = 310.15
DT_S = 0.03
"""The fixed electrode's time step (``run --dt``'s default); other runs are the dt study."""
REGION_DEPTH_MM = 12.0
"""The fixed electrode's working region's depth (``run --depth-mm``'s default); runs with
another are the reference-depth check."""


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
        "leaves": leaves_fine_region(d),
    }


def _region_mm(d: dict[str, np.ndarray]) -> float:
    """The working region's depth in mm the run was made with (0: a uniform grid)."""
    return float(d["depth_mm"]) if "depth_mm" in d else REGION_DEPTH_MM


def _standard_depth(d: dict[str, np.ndarray]) -> bool:
    """Whether a fixed-electrode run has the scene's region depth (or no region): the ladders'
    runs."""
    return _region_mm(d) in (0.0, REGION_DEPTH_MM)


def leaves_fine_region(d: dict[str, np.ndarray]) -> float:
    """The first time in s the crater's floor lies below the graded grid's working region
    (``depth_mm``; from then on it digs in coarser cells); NaN: it never did, or no region."""
    region_m = _region_mm(d) * 1e-3
    if region_m <= 0:
        return math.nan
    return _first(d["time_s"], d["depth_m"] > region_m)


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
                cut = _at(d["time_s"], d["cut_m3"], t)
                ref = _at(runs[top]["time_s"], runs[top]["cut_m3"], t)
                cells.append(f"{_fmt(cut, 1e9)} | {_fmt(cut / ref if ref else math.nan, 1.0, 3)}")
            lines.append(
                f"| {float(d['fine_mm']):g} mm | {_surface_mm(d):g} | {int(d['n_nodes'])} | "
                f"{_fmt(s_['t100_interp'], 1.0, 4)} | {_fmt(s_['cut_interp'], 1.0, 4)} | "
                f"{_fmt(s_['cut_interp'] / fin['cut_interp'], 1.0, 3)} | "
                + " | ".join(cells)
                + f" | {_fmt(s_['leaves'])} |"
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


def _depth_lines(runs: dict[str, dict[str, np.ndarray]], deeper: list[str]) -> list[str]:
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
            c3 = _at(t, cut, 3.0)
            ratios = [
                _fmt(_at(runs[r]["time_s"], runs[r]["cut_m3"], 3.0) / c3, 1.0, 3)
                if r in runs and c3
                else "—"
                for r in ("fixed_0.4mm", "fixed_0.4mm_s0.1")
            ]
            lines.append(
                f"| {kk} | {_region_mm(d):g} | {int(d['n_nodes'])} | {float(t[-1]):.2f} | "
                f"{_fmt(leaves_fine_region(d))} | {_fmt(_at(t, cut, 1.62), 1e9)} | "
                f"{_fmt(_at(t, cut, 2.4), 1e9)} | {_fmt(c3, 1e9)} | "
                f"{_fmt(_at(t, d['depth_m'], 3.0), 1e3)} | {ratios[0]} | {ratios[1]} |"
            )
    return lines


ENERGY_TIMES_S = (1.62, 3.0)
"""Simulated times at which the Joule energy per removed volume is compared."""


def joule_energy(d: dict[str, np.ndarray], t: float) -> float:
    """Electric energy (J) delivered by simulated time ``t``: the steps' powers times dt."""
    time_s, power = d["time_s"], d["power_w"]
    return float(power[time_s <= t + 1e-9].sum() * float(d["dt_s"]))


def _energy_lines(runs: dict[str, dict[str, np.ndarray]], keys: list[str]) -> list[str]:
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
            cut = _at(d["time_s"], d["cut_m3"], t) * 1e9
            if not cut > 0:
                continue
            e = joule_energy(d, t)
            rows.append((float(d["fine_mm"]), e / cut))
            lines.append(
                f"| {t:g} | {k} | {float(d['fine_mm']):g} | {_region_mm(d):g} | {e:.1f} | "
                f"{cut:.1f} | {e / cut:.3f} |"
            )
        hs = sorted({h for h, _ in rows}, reverse=True)
        if len(hs) >= 2:
            b, a = np.polyfit([h for h, _ in rows], [r for _, r in rows], 1)
            by_h = {h: float(np.mean([r for hh, r in rows if hh == h])) for h in hs}
            order = observed_order(*(by_h[h] for h in hs[:3])) if len(hs) >= 3 else math.nan
            fits.append(
                f"- t = {t:g} s: J/mm^3 = {a:.3f} + {b:.3f} h (h -> 0: {a:.3f}; b / a = "
                f"{b / a:.2f} per mm), observed order {_fmt(order)}; at the fit the 0.4 mm grid "
                f"removes {100 * a / (a + 0.4 * b):.0f} % and the 0.2 mm grid "
                f"{100 * a / (a + 0.2 * b):.0f} % of the volume per joule of h -> 0."
            )
    return lines + (["", *fits] if fits else [])


def _fine_z_mm(d: dict[str, np.ndarray]) -> float:
    """The run's cell height over the working region in mm (its fine spacing unless set)."""
    return float(d["fine_z_mm"]) if "fine_z_mm" in d else float(d["fine_mm"])


def _cubic(d: dict[str, np.ndarray]) -> bool:
    """Whether the run's working region has cubic cells (no cell height of its own)."""
    return math.isclose(_fine_z_mm(d), float(d["fine_mm"]))


def _axis_lines(runs: dict[str, dict[str, np.ndarray]], keys: list[str]) -> list[str]:
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
    for k in sorted(rows, key=lambda k: (-float(runs[k]["fine_mm"]), -_fine_z_mm(runs[k]))):
        d = runs[k]
        cut, depth = _at(d["time_s"], d["cut_m3"], t), _at(d["time_s"], d["depth_m"], t)
        lines.append(
            f"| {k} | {float(d['fine_mm']):g} | {_fine_z_mm(d):g} | {int(d['n_nodes'])} | "
            f"{_fmt(summary(d)['cut_interp'], 1.0, 3)} | {_fmt(cut, 1e9)} | "
            f"{_fmt(depth, 1e3)} | {_fmt(cut / depth if depth else math.nan, 1e6)} | "
            f"{_fmt(joule_energy(d, t) / (cut * 1e9) if cut else math.nan, 1.0, 3)} | "
            f"{float(np.median(d['wall_s'])):.2f} |"
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
    """``convergence.md`` and ``convergence.png`` in ``RESULTS`` from every run and JSON there;
    the table is printed too."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    every = {
        p.stem.removeprefix("convergence_"): dict(np.load(p))
        for p in RESULTS.glob("convergence_*.npz")
    }
    deeper = sorted(k for k, d in every.items() if k.startswith("fixed") and not _standard_depth(d))
    tall = sorted(k for k, d in every.items() if k.startswith("fixed") and not _cubic(d))
    runs = {k: d for k, d in every.items() if k not in deeper and k not in tall}
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
        "| depth 6 s mm | crater leaves the fine region s | peak p kPa | median step s "
        "| max RSS MiB |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for k in fixed:
        s = sums[k]
        lines.append(
            f"| {_grid_label(k, runs[k])} | {s['nodes']:.0f} | {s['t_end']:.2f} | "
            f"{s['power0']:.2f} | {s['power0'] / ref_w:.3f} | {_fmt(s['t100'])} | "
            f"{_fmt(s['t100_interp'], 1.0, 3)} | {_fmt(s['first_cut'])} | "
            f"{_fmt(s['cut_interp'], 1.0, 3)} | {_fmt(s['cut3'], 1e9)} | "
            f"{_fmt(s['depth3'], 1e3)} | {_fmt(s['cut6'], 1e9)} | {_fmt(s['depth6'], 1e3)} | "
            f"{_fmt(s['leaves'])} | {s['p_peak'] / 1e3:.0f} | {s['step_median']:.2f} | "
            f"{s['rss']:.0f} |"
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
            rels = [
                s[q] / finest[q] - 1 if finest[q] and math.isfinite(finest[q]) else math.nan
                for q in ("power0", "first_cut", "cut_interp", "cut3")
            ]
            lines.append(
                f"| {k.removeprefix('fixed_')} | "
                + " | ".join(_fmt(v, 100, 1) + " %" for v in rels)
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
    lines += _depth_lines(every, deeper)
    lines += _energy_lines(every, graded + deeper)
    lines += _axis_lines(every, tall)
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
