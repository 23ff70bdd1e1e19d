"""One saved run of ``convergence.py run`` read back: where the runs live, what each was made
with, and the figures the report's tables take from it.

A run is the dict of arrays ``convergence.py run`` saves (``convergence_<tag>.npz``): per step
the time, wall time, delivered power, peak temperature and pressure, the strain energy on the
front, the cut volume and the crater depth, and the grid and model it ran with. ``summary``
gives its times to 100 C and to the first cut (per step and, by ``crossing``, within the step),
the crater at 3 / 6 / 12 s, peak pressure, power, step time and memory; ``drilling_rate`` its
deepening rate; ``observed_order`` the order of a quantity over three halvings.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

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


def first_time(time_s: np.ndarray, mask: np.ndarray) -> float:
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


def at(time_s: np.ndarray, values: np.ndarray, t: float) -> float:
    idx = np.flatnonzero(np.abs(time_s - t) < 1e-6)
    return float(values[idx[0]]) if idx.size else math.nan


def fmt(v: float, scale: float = 1.0, digits: int = 2) -> str:
    return "—" if not math.isfinite(v) else f"{v * scale:.{digits}f}"


def summary(d: dict[str, np.ndarray]) -> dict[str, float]:
    t = d["time_s"]
    return {
        "t_end": float(t[-1]),
        "t100": first_time(t, d["t_max_k"] >= T_BOIL_K),
        "t100_interp": crossing(t, d["t_max_k"], T_BOIL_K, T_INITIAL_K),
        "first_cut": first_time(t, d["cut_m3"] > 0),
        "cut_interp": crossing(t, d["w_front"], float(d["kappa"]), 0.0)
        if "w_front" in d
        else math.nan,
        "cut3": at(t, d["cut_m3"], 3.0),
        "depth3": at(t, d["depth_m"], 3.0),
        "cut6": at(t, d["cut_m3"], 6.0),
        "depth6": at(t, d["depth_m"], 6.0),
        "cut12": at(t, d["cut_m3"], 12.0),
        "depth12": at(t, d["depth_m"], 12.0),
        "p_peak": float(d["p_max_pa"].max()),
        "power0": float(d["power_w"][0]),
        "step_median": float(np.median(d["wall_s"][1:] if t.size > 1 else d["wall_s"])),
        "rss": float(d["max_rss_mib"]),
        "nodes": float(d["n_nodes"]),
        "leaves": leaves_fine_region(d),
    }


def region_mm(d: dict[str, np.ndarray]) -> float:
    """The working region's depth in mm the run was made with (0: a uniform grid)."""
    return float(d["depth_mm"]) if "depth_mm" in d else REGION_DEPTH_MM


def standard_depth(d: dict[str, np.ndarray]) -> bool:
    """Whether a fixed-electrode run has the scene's region depth (or no region): the ladders'
    runs."""
    return region_mm(d) in (0.0, REGION_DEPTH_MM)


def leaves_fine_region(d: dict[str, np.ndarray]) -> float:
    """The first time in s the crater's floor lies below the graded grid's working region
    (``depth_mm``; from then on it digs in coarser cells); NaN: it never did, or no region."""
    region_m = region_mm(d) * 1e-3
    if region_m <= 0:
        return math.nan
    return first_time(d["time_s"], d["depth_m"] > region_m)


def observed_order(a: float, b: float, c: float) -> float:
    """Order p from three values at spacings h, h/2, h/4: log2(|a - b| / |b - c|)."""
    if not all(math.isfinite(v) for v in (a, b, c)) or b == c or a == b:
        return math.nan
    return math.log2(abs(a - b) / abs(b - c))


def grid_label(k: str, d: dict[str, np.ndarray]) -> str:
    return f"{k.split('_', 1)[1]} ({'x'.join(str(n) for n in d['shape'])})"


def contact_model(d: dict[str, np.ndarray]) -> str:
    """The run's contact model ('flat' for older runs)."""
    return str(d["contact"]) if "contact" in d else "flat"


def removal(d: dict[str, np.ndarray]) -> str:
    """The run's ``level_set.removal`` ('threshold' for older runs)."""
    return str(d["removal"]) if "removal" in d else "threshold"


def surface_mm(d: dict[str, np.ndarray]) -> float:
    """The run's cell height at the top surface in mm (0: the fine spacing, older runs)."""
    return float(d["surface_mm"]) if "surface_mm" in d else 0.0


def fine_z_mm(d: dict[str, np.ndarray]) -> float:
    """The run's cell height over the working region in mm (its fine spacing unless set)."""
    return float(d["fine_z_mm"]) if "fine_z_mm" in d else float(d["fine_mm"])


def cubic(d: dict[str, np.ndarray]) -> bool:
    """Whether the run's working region has cubic cells (no cell height of its own)."""
    return math.isclose(fine_z_mm(d), float(d["fine_mm"]))


def length_mm(d: dict[str, np.ndarray]) -> float:
    """The run's non-local length of the cut driver in mm (0: the local law, older runs)."""
    return float(d["length_mm"]) if "length_mm" in d else 0.0


def joule_energy(d: dict[str, np.ndarray], t: float) -> float:
    """Electric energy (J) delivered by simulated time ``t``: the steps' powers times dt."""
    time_s, power = d["time_s"], d["power_w"]
    return float(power[time_s <= t + 1e-9].sum() * float(d["dt_s"]))


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
