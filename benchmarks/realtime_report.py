"""The tables and plots of ``realtime.py run``: what a run measured, written and read back.

``write_run`` writes ``realtime.md`` (per scene and mode: step times, real-time factors, time per
effect, errors against the full mode), ``realtime.json`` (every step's record, which
``read_run`` reads back for ``realtime.py report``), ``realtime.png`` (wall time per step) and
``realtime_errors.png`` (each mode's errors per step against issue #25's targets).
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

EFFECTS = ("electric", "thermal", "vaporization", "mechanics", "dissection")
"""The effects whose wall time a run records per step."""


def command_line(a: argparse.Namespace) -> str:
    """The ``run`` command that gave these results."""
    parts = [
        f"python benchmarks/realtime.py run --scenes {' '.join(a.scenes)} --grids "
        f"{' '.join(a.grids)} --steps {a.steps}"
    ]
    if getattr(a, "from_start", False):
        parts.append("--from-start")
    if getattr(a, "from_step", None) is not None:
        parts.append(f"--from-step {a.from_step}")
    if a.tight:
        parts.append("--tight")
    if getattr(a, "removal", "threshold") != "threshold":
        parts.append(f"--removal {a.removal}")
    if a.tolerances:
        parts.append("--tolerances " + " ".join(f"{t:g}" for t in a.tolerances))
    parts += [f"--variant '{v}'" for v in getattr(a, "variant", [])]
    return " ".join(parts)


SE_TARGET = 0.01
T_TARGET_K = 0.1
"""Issue #25's accuracy targets against the full solve: max strain-energy error, max temperature
error."""


def first_over(errors: list[float], target: float) -> str:
    """The first measured step (1-based) whose error exceeds ``target``, '-' when none does."""
    return next((str(i + 1) for i, e in enumerate(errors) if e > target), "-")


def cutting_steps(cut_m3: list[float]) -> list[int]:
    """Indices of the steps from the first with a cut on (all of them when none cuts)."""
    first = next((i for i, c in enumerate(cut_m3) if c > 0), None)
    return list(range(len(cut_m3))) if first is None else list(range(first, len(cut_m3)))


def write_run(
    runs: dict,
    a: argparse.Namespace | str,
    started: str,
    out: Path,
    load: tuple[float, ...] | None = None,
) -> None:
    """The table (``realtime.md``), every step's record (``realtime.json``, which ``report``
    reads back) and the plots of ``runs``; ``a``: the run's arguments, or its command line;
    ``load``: the load average the run ended with (default: now's)."""
    command = a if isinstance(a, str) else command_line(a)
    steps = max(len(r["wall_s"]) for run in runs.values() for r in run["rec"].values())
    load = load or os.getloadavg()
    from_start = any(run.get("from_start") for run in runs.values())
    apart = all("tets_apart" in r for run in runs.values() for r in run["rec"].values())
    later = sorted({run["from_step"] for run in runs.values() if run.get("from_step")})
    where = (
        "from its first step (a whole run: heating, the first vaporization and mechanics solve, "
        "the cut)"
        if from_start
        else f"from its state after {' / '.join(map(str, later))} steps in its own settings"
        if later
        else "checkpoint two steps after the first cut (or after the warm-up where it does not cut)"
    )
    lines = [
        "# Real time: a cutting step, full against incremental",
        "",
        f"`{command}` (started {started}): each scene {where}, {steps} steps per mode, "
        "the modes stepped in lockstep. A 2-core machine that other jobs may share (load "
        f"average when written: {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f}): wall times are "
        "inflated alike for every mode, read the ratios. Errors are against the full mode at "
        "the same step (strain energy: the paper's relative L2 over tets), their max over "
        "every measured step. Effect columns: median wall time of each effect per step (s). "
        "Real-time factor: dt / median step; sustained factor: dt / mean step, which counts the "
        "interval's full solve (every `mechanics.full_every` solves) that the median hides. "
        "*First step over*: the first measured step whose error passes the issue's target. "
        "*Cutting phase*: the steps from the mode's first cut on (every step from a checkpoint "
        "after the cut); *cut from*: the first measured step with a cut."
        + (
            " *Tets cut apart*: the most tets whose removed state differs from the full mode's "
            "at one step, on how many steps any does and the first such step; *max T error "
            "before*: the max temperature error over the steps before that one (once one tet is "
            "cut in one mode and not in the other, the current takes another path and the "
            "temperatures part; the error decays by diffusion only after the cuts agree again)."
            if apart
            else ""
        ),
        "",
        "| scene | grid | nodes | first cut | mode | median step s | p90 step s | mean step s | "
        "x full | real-time factor | sustained factor | cutting phase median / p90 s | "
        "cut from | electric | thermal | mechanics | dissection | local mechanics steps | "
        "max SE error | mean SE error | max T error K | first step over 1 % SE / 0.1 K | "
        "cut volume vs full |"
        + (" tets cut apart (steps, first) | max T error before K |" if apart else ""),
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
        "---|" + ("---|---|" if apart else ""),
    ]
    for (name, _grid), run in runs.items():
        rec, dt_s = run["rec"], run["dt_s"]
        base = float(np.median(rec["full"]["wall_s"]))
        cut_at = "none" if run["first_cut"] is None else f"step {run['first_cut']}"
        if run.get("from_start"):
            cut_at = "from step 0"
        for m, r in rec.items():
            med, p90 = float(np.median(r["wall_s"])), float(np.percentile(r["wall_s"], 90))
            mean = float(np.mean(r["wall_s"]))
            phase = cutting_steps(r["cut_m3"])
            walls = np.asarray(r["wall_s"])[phase]
            cut_from = next((i + 1 for i, c in enumerate(r["cut_m3"]) if c > 0), None)
            cut, cut_ref = r["cut_m3"][-1], rec["full"]["cut_m3"][-1]
            rel_cut = (cut - cut_ref) / cut_ref if cut_ref > 0 else 0.0
            effects = " | ".join(f"{np.median(r[e]):.3f}" for e in EFFECTS if e != "vaporization")
            lines.append(
                f"| {name} | {run['grid_label']} | {run['nodes']:,} | {cut_at} | {m} | {med:.2f} "
                f"| {p90:.2f} | {mean:.2f} | {med / base:.2f} | {dt_s / med:.3f} | "
                f"{dt_s / mean:.3f} | {np.median(walls):.3f} / {np.percentile(walls, 90):.3f} | "
                f"{'-' if cut_from is None else cut_from} | {effects} | "
                f"{int(sum(r['local']))}/{len(r['local'])} | {max(r['se_err']):.2e} | "
                f"{np.mean(r['se_err']):.2e} | {max(r['dT_k']):.2e} | "
                f"{first_over(r['se_err'], SE_TARGET)} / {first_over(r['dT_k'], T_TARGET_K)} | "
                f"{rel_cut:+.2e} |" + (apart_cells(r) if apart else "")
            )
    out.mkdir(parents=True, exist_ok=True)
    (out / "realtime.md").write_text("\n".join(lines) + "\n")
    (out / "realtime.json").write_text(
        json.dumps(
            {
                "command": command,
                "load": list(load),
                "started": started,
                "runs": [
                    {
                        "scene": n,
                        "grid": g,
                        **{k: v for k, v in run.items() if k != "rec"},
                        "modes": run["rec"],
                    }
                    for (n, g), run in runs.items()
                ],
            },
            indent=1,
        )
    )
    plot_run(runs, out)
    plot_errors(runs, out)
    print("\n".join(lines))


def apart_cells(r: dict[str, list[float]]) -> str:
    """The two cut-agreement cells of a mode's row: the most tets whose removed state differs
    from the full mode's at one step (on how many steps any does, and the first, 1-based), and
    the max temperature error over the steps before that first one (K; every step if none)."""
    apart = np.asarray(r["tets_apart"])
    parted = np.flatnonzero(apart)
    first = int(parted[0]) if parted.size else apart.size
    before = np.asarray(r["dT_k"])[:first]
    worst = f"{before.max():.2e}" if before.size else "-"
    when = f", {first + 1}" if parted.size else ""
    return f" {int(apart.max())} ({parted.size}{when}) | {worst} |"


def read_run(folder: Path) -> tuple[dict, str, str, tuple[float, ...] | None]:
    """(runs, command, started, load average) of a ``run``'s ``realtime.json`` in ``folder``."""
    saved = json.loads((folder / "realtime.json").read_text())
    runs = {
        (r["scene"], r["grid"]): {
            **{k: v for k, v in r.items() if k not in ("scene", "grid", "modes")},
            "rec": r["modes"],
        }
        for r in saved["runs"]
    }
    load = saved.get("load")
    return runs, saved["command"], saved["started"], None if load is None else tuple(load)


def plot_errors(runs: dict, out: Path) -> None:
    """Per scene, each approximate mode's strain-energy and temperature error against the full
    mode at every step, with the issue's targets (1 %, 0.1 K), and where recorded the tets whose
    removed state differs from the full mode's (dotted, right axis): ``realtime_errors.png``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(runs)
    fig, axes = plt.subplots(n, 2, figsize=(10, 3.2 * n), squeeze=False)
    for (ax_se, ax_t), ((name, _grid), run) in zip(axes, runs.items(), strict=True):
        apart_ax = None
        for m, r in run["rec"].items():
            if m == "full":
                continue
            steps = np.arange(1, len(r["se_err"]) + 1)
            ax_se.plot(steps, np.maximum(r["se_err"], 1e-8), label=m, lw=1)
            line = ax_t.plot(steps, np.maximum(r["dT_k"], 1e-6), label=m, lw=1)[0]
            if "tets_apart" in r and any(r["tets_apart"]):
                apart_ax = apart_ax or ax_t.twinx()
                apart_ax.step(steps, r["tets_apart"], color=line.get_color(), lw=0.6, ls=":")
                apart_ax.set_ylabel("tets cut apart (dotted)", fontsize=7)
        for ax, target, what in ((ax_se, SE_TARGET, "SE error"), (ax_t, T_TARGET_K, "T error (K)")):
            ax.axhline(target, color="k", lw=0.8, ls="--", label="target")  # SE_TARGET, T_TARGET_K
            ax.set_yscale("log")
            ax.set_xlabel("step")
            ax.set_ylabel(what)
            ax.set_title(f"{name}, {run['grid_label']}: against full", fontsize=9)
        ax_se.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(out / "realtime_errors.png", dpi=100)
    plt.close(fig)


def plot_run(runs: dict, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(runs)
    cols = min(n, 3)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 3.5 * rows), squeeze=False)
    for ax, ((name, _grid), run) in zip(axes.ravel(), runs.items(), strict=False):
        for m, r in run["rec"].items():
            ax.plot(r["wall_s"], marker="o", label=m)
        ax.axhline(run["dt_s"], color="k", lw=0.8, ls="--", label="dt (real time)")
        ax.set_title(f"{name}, {run['grid_label']}", fontsize=9)
        ax.set_xlabel("step after the checkpoint")
        ax.set_ylabel("wall time per step (s)")
        ax.set_yscale("log")
        ax.legend(fontsize=7)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    fig.tight_layout()
    fig.savefig(out / "realtime.png", dpi=100)
    plt.close(fig)
