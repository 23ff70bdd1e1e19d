"""The accuracy-cost report's rows and outputs: the Row of one (scene, variant), the Pareto
front, and the files written from the rows (report.md, report.csv, report.json, two plots)."""

from __future__ import annotations

import csv
import json
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Row:
    """One line of the report (errors are relative, times in s, memory in MB)."""

    scene: str
    variant: str
    backend: str
    rtol: float
    grid: str
    steps: int
    step_median_s: float
    step_p10_s: float
    step_p90_s: float
    mechanics_median_s: float
    speedup_vs_reference: float
    peak_rss_mb: float
    se_error_max: float
    se_error_mean: float
    displacement_error_max: float
    cut_volume_error: float
    crater_depth_error: float
    error_slope_per_s: float
    error_grows: bool
    pareto: bool = False
    failed: str | None = None
    model: str | None = None
    guard_tolerance: float | None = None
    correction: str = "none"  # cnn: "patch" or "none" (fem and pgd: "none")
    compared_steps: int = 0  # steps where the reference had strain energy to compare against
    incremental: bool = False  # fem: the previous-displacement predictor (issue #25)
    full_every: int = 10
    interval_tolerance: float = 0.0  # rows measured before it existed: the FEM-tight interval
    dt_s: float | None = None  # the variant's time step (None: the scene's; before issue #25)
    guard: str = "auto"

    @property
    def worst_error(self) -> float:
        """The error the Pareto front ranks by: strain energy, cut volume or crater depth."""
        return max(self.se_error_max, self.cut_volume_error, self.crater_depth_error)


PUBLISHED = (
    ("fixed-electrode", "hybrid-CNN", "6.9 %"),
    ("fixed-electrode", "hybrid-PGD, 15 modes", "13 %"),
    ("moving-electrode (paper: 12.35 mm/s)", "hybrid-CNN", "9.6 %"),
    ("moving-electrode (paper: 12.35 mm/s)", "hybrid-PGD, 15 modes", "69 %"),
    ("(cross-validation)", "CNN", "10.3 % (mean)"),
)
"""The seed paper's headline errors (BENCHMARKS.md), printed beside ours and marked as published."""


def mark_pareto(rows: list[Row]) -> list[Row]:
    """A row is on the front when no other row of its scene is both faster and more accurate.

    Accuracy here is the worst of the strain-energy, cut-volume and crater-depth errors, so a
    coarse grid whose own reference never cuts is not 'exact' just because it has nothing to compare.
    """
    out = []
    for r in rows:
        dominated = r.failed is not None or any(
            o is not r
            and o.scene == r.scene
            and o.failed is None
            and o.step_median_s <= r.step_median_s
            and o.worst_error <= r.worst_error
            and (o.step_median_s < r.step_median_s or o.worst_error < r.worst_error)
            for o in rows
        )
        out.append(Row(**{**asdict(r), "pareto": not dominated}))
    return out


def write_outputs(
    rows: list[Row],
    curves: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]],
    out: Path,
    *,
    steps: int,
    command: str | None = None,
) -> None:
    """report.md (Markdown table), report.csv, report.json (what the API serves) and two PNGs."""
    stamp = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    with open(out / "report.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(asdict(rows[0]))) if rows else None
        if w:
            w.writeheader()
            for r in rows:
                w.writerow(asdict(r))
    (out / "report.json").write_text(
        json.dumps(
            {"generated": stamp, "steps": steps, "rows": [asdict(r) for r in rows]}, indent=1
        )
    )
    lines = [
        "# Accuracy vs cost",
        "",
        *([f"`{command}`", ""] if command else []),
        f"Generated {stamp}; {steps} steps per run. Errors are against FEM at rtol 1e-10 on the same grid "
        "(cut volume and crater depth: against the finest grid's reference, a time-step variant's "
        "against its dt 0.01 s reference); 'compared steps' counts "
        "the steps in which the reference had strain energy at all (0: the run never reached the "
        "mechanics, so its errors are 0 by construction); speed-up is against that reference, "
        "per simulated second (a variant with its own dt is measured against FEM at rtol 1e-10 "
        "and dt 0.01 s on the same grid, at their common times). "
        "Times are per full step "
        "(median, p10-p90), measured one variant at a time in its own process; read the ratios.",
        "",
        "| scene | variant | grid | dt s | step s (p10-p90) | mech s | speed-up | peak MB | compared steps | SE err max | SE err mean | u err max | cut vol err | depth err | error grows | Pareto |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if r.failed:
            lines.append(f"| {r.scene} | {r.variant} | {r.grid} | failed: {r.failed} |" + " |" * 12)
            continue
        lines.append(
            f"| {r.scene} | {r.variant} | {r.grid} | {r.dt_s if r.dt_s is not None else '-'} "
            f"| {r.step_median_s:.3f} ({r.step_p10_s:.3f}-{r.step_p90_s:.3f}) "
            f"| {r.mechanics_median_s:.3f} | {r.speedup_vs_reference:.2f}x | {r.peak_rss_mb:.0f} "
            f"| {r.compared_steps} | {r.se_error_max:.2e} | {r.se_error_mean:.2e} | {r.displacement_error_max:.2e} "
            f"| {r.cut_volume_error:.1%} | {r.crater_depth_error:.1%} | {'yes' if r.error_grows else 'no'} "
            f"| {'*' if r.pareto else ''} |"
        )
    lines += [
        "",
        "Published figures of the seed paper (Han, Rahul & De), beside ours for comparison — "
        "**published, not measured here** (its grid 64x64x128, its own machines):",
        "",
        "| scene | variant | published max strain-energy error |",
        "|---|---|---|",
        *(f"| {scene} | {variant} (published) | {err} |" for scene, variant, err in PUBLISHED),
    ]
    (out / "report.md").write_text("\n".join(lines) + "\n")
    _plots(rows, curves, out)


def _plots(
    rows: list[Row], curves: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]], out: Path
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in rows if not r.failed]
    scenes = sorted({r.scene for r in ok})
    fig, axes = plt.subplots(
        1, max(len(scenes), 1), figsize=(6 * max(len(scenes), 1), 4.5), squeeze=False
    )
    for ax, scene in zip(axes[0], scenes, strict=False):
        rs = [r for r in ok if r.scene == scene]
        for r in rs:
            ax.scatter(r.step_median_s, max(r.se_error_max, 1e-12), marker="o" if r.pareto else "x")
            ax.annotate(r.variant, (r.step_median_s, max(r.se_error_max, 1e-12)), fontsize=7)
        front = sorted((r for r in rs if r.pareto), key=lambda r: r.step_median_s)
        ax.plot(
            [r.step_median_s for r in front],
            [max(r.se_error_max, 1e-12) for r in front],
            "k--",
            lw=0.8,
        )
        ax.set(
            xscale="log",
            yscale="log",
            xlabel="time per step, s (median)",
            ylabel="max strain-energy error",
            title=scene,
        )
    fig.tight_layout()
    fig.savefig(out / "error_vs_cost.png", dpi=120)
    plt.close(fig)
    fig, axes = plt.subplots(
        1, max(len(scenes), 1), figsize=(6 * max(len(scenes), 1), 4.5), squeeze=False
    )
    for ax, scene in zip(axes[0], scenes, strict=False):
        for (s, name), (t, se) in curves.items():
            if s == scene and se.size and np.isfinite(se).any():
                ax.plot(
                    t, np.where(np.isfinite(se), np.maximum(se, 1e-12), np.nan), label=name, lw=1
                )
        ax.set(yscale="log", xlabel="simulated time, s", ylabel="strain-energy error", title=scene)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "error_vs_time.png", dpi=120)
    plt.close(fig)
