"""The accuracy-cost report: every variant of every scene against the FEM reference, side by side.

Each variant runs in its own process (so peak memory is its own), once: its record and fields are
kept in the output folder keyed by a hash of everything that decides the result, so an
interrupted report resumes where it stopped and a finished variant is never re-run.
"""

from __future__ import annotations

import csv
import json
import multiprocessing as mp
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from tqdm import tqdm

from diathermy.errors import SceneError
from diathermy.physics.strain_energy import relative_strain_energy_error
from diathermy.report.measure import RunRecord, load_fields, run_variant
from diathermy.report.variants import Variant, reference_for
from diathermy.scene import Scene


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


def _run(
    scene: Scene, variant: Variant, steps: int, out: Path, pool: ProcessPoolExecutor
) -> RunRecord:
    """The variant's record over the simulated time of ``steps`` of the scene's dt, from disk
    if it was measured before with the same key."""
    steps = variant.steps_for(scene, steps)
    key = variant.key(scene, steps)
    stem = out / "runs" / f"{scene.name}--{variant.name}--{key}"
    # not with_suffix: a variant's name may hold a dot ("fem-dt0.1")
    rec_path, fields_path = stem.parent / f"{stem.name}.json", stem.parent / f"{stem.name}.h5"
    if rec_path.exists() and fields_path.exists():
        rec = RunRecord.from_json(rec_path.read_text())
        if rec.error is None:
            return rec
    stem.parent.mkdir(parents=True, exist_ok=True)
    text = pool.submit(
        run_variant, scene.model_dump_json(), variant, steps, key, str(fields_path)
    ).result()
    rec_path.write_text(text)
    return RunRecord.from_json(text)


def common_steps(t: np.ndarray, t_ref: np.ndarray, tol_s: float = 1e-9) -> np.ndarray:
    """For each time of t (s), the index of the same time in t_ref (ascending), or -1 where it
    has none (a variant at dt 0.03 s meets a reference at 0.01 s every third step)."""
    t, t_ref = np.asarray(t, float), np.asarray(t_ref, float)
    out = np.full(t.size, -1, dtype=np.int64)
    if t_ref.size == 0:
        return out
    j = np.clip(np.searchsorted(t_ref, t - tol_s), 0, t_ref.size - 1)
    hit = np.abs(t_ref[j] - t) <= tol_s
    out[hit] = j[hit]
    return out


def _errors(
    var: Path, ref: Path, t: np.ndarray, t_ref: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per-step strain-energy and displacement errors against the reference at the same time
    (NaN where the reference is at rest or has no step at that time)."""
    W, u = load_fields(var)
    W_ref, u_ref = load_fields(ref)
    se = np.full(W.shape[0], np.nan)
    du = np.full(W.shape[0], np.nan)
    for i, j in enumerate(common_steps(t[: W.shape[0]], t_ref[: W_ref.shape[0]])):
        if j >= 0 and np.any(W_ref[j]):
            se[i] = relative_strain_energy_error(W[i].astype(float), W_ref[j].astype(float))
            du[i] = float(np.linalg.norm(u[i] - u_ref[j]) / np.linalg.norm(u_ref[j]))
    return se, du


def _fields_path(out: Path, scene: Scene, rec: RunRecord) -> Path:
    return out / "runs" / f"{scene.name}--{rec.variant.name}--{rec.key}.h5"


def _row(
    scene: Scene, rec: RunRecord, ref: RunRecord, out: Path, finest: RunRecord
) -> tuple[Row, np.ndarray]:
    grid = "x".join(str(n) for n in rec.grid)
    if rec.error is not None:
        nan = float("nan")
        return Row(
            scene.name,
            rec.variant.name,
            rec.variant.backend,
            rec.variant.rtol,
            grid,
            rec.steps,
            nan,
            nan,
            nan,
            nan,
            nan,
            rec.peak_rss_mb,
            nan,
            nan,
            nan,
            nan,
            nan,
            nan,
            False,
            failed=rec.error,
            model=rec.variant.model,
            guard_tolerance=rec.variant.guard_tolerance,
            correction=rec.variant.correction,
            incremental=rec.variant.incremental,
            full_every=rec.variant.full_every,
        ), np.array([])
    step = np.asarray(rec.step_s)
    mech = np.asarray(rec.effect_s.get("mechanics", [0.0]))
    t = np.asarray(rec.time_s)
    se, du = _errors(
        _fields_path(out, scene, rec), _fields_path(out, scene, ref), t, np.asarray(ref.time_s)
    )
    dt, dt_ref = rec.variant.dt_s or scene.dt_s, ref.variant.dt_s or scene.dt_s
    active = np.isfinite(se)
    slope = float(np.polyfit(t[active], se[active], 1)[0]) if active.sum() >= 3 else 0.0
    mean = float(np.nanmean(se)) if active.any() else 0.0
    span = float(t[active].max() - t[active].min()) if active.any() else 0.0
    # the crater against the finest grid's reference, or a time step's against its dt 0.01 one
    outcome = ref if rec.variant.dt_s is not None else finest
    cut_ref, depth_ref = outcome.cut_volume_m3[-1], outcome.crater_depth_m[-1]
    return Row(
        scene=scene.name,
        variant=rec.variant.name,
        backend=rec.variant.backend,
        rtol=rec.variant.rtol,
        grid=grid,
        steps=rec.steps,
        step_median_s=float(np.median(step)),
        step_p10_s=float(np.percentile(step, 10)),
        step_p90_s=float(np.percentile(step, 90)),
        mechanics_median_s=float(np.median(mech)),
        speedup_vs_reference=float((np.median(ref.step_s) / dt_ref) / (np.median(step) / dt)),
        peak_rss_mb=rec.peak_rss_mb,
        se_error_max=float(np.nanmax(se)) if active.any() else 0.0,
        se_error_mean=mean,
        displacement_error_max=float(np.nanmax(du)) if active.any() else 0.0,
        cut_volume_error=abs(rec.cut_volume_m3[-1] - cut_ref) / cut_ref if cut_ref > 0 else 0.0,
        crater_depth_error=abs(rec.crater_depth_m[-1] - depth_ref) / depth_ref
        if depth_ref > 0
        else 0.0,
        error_slope_per_s=slope,
        error_grows=bool(slope * span > 0.5 * mean) if mean > 0 else False,
        model=rec.variant.model,
        guard_tolerance=rec.variant.guard_tolerance,
        correction=rec.variant.correction,
        compared_steps=int(active.sum()),
        incremental=rec.variant.incremental,
        full_every=rec.variant.full_every,
        dt_s=dt,
        guard=rec.variant.guard,
    ), se


def _mark_pareto(rows: list[Row]) -> list[Row]:
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


def accuracy_cost_report(
    scenes: list[Scene],
    variants: list[Variant],
    *,
    steps: int,
    out: Path,
    progress: bool = True,
    on_row: Callable[[Row], None] | None = None,
    command: str | None = None,
) -> list[Row]:
    """Run every (scene, variant) and its references; write report.md, report.csv, report.json, plots.

    The scenes are on uniform grids (the surrogates' and the coarse variant's); a graded scene
    (``resolution``) is refused: put it on one with ``Scene.on_uniform_grid``.
    """
    for scene in scenes:
        if scene.resolution is not None:
            raise SceneError(
                f"accuracy-cost compares uniform grids; scene {scene.name!r} is graded "
                "(resolution): give it a uniform grid (--grid NZxNYxNX)"
            )
    out.mkdir(parents=True, exist_ok=True)
    rows: list[Row] = []
    curves: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = {}
    jobs = [(s, v) for s in scenes for v in variants]
    ctx = mp.get_context("spawn")  # a fresh interpreter per variant: its peak memory is its own
    bar = tqdm(total=len(jobs), disable=not progress, unit="variant", desc="accuracy-cost")
    for scene in scenes:
        grids = sorted({v.grid or scene.grid for v in variants}, key=lambda g: int(np.prod(g)))
        finest_grid = grids[-1]
        with ProcessPoolExecutor(max_workers=1, mp_context=ctx, max_tasks_per_child=1) as pool:
            finest = _run(scene, reference_for(Variant("f", grid=finest_grid)), steps, out, pool)
            for variant in variants:
                bar.set_postfix(scene=scene.name, variant=variant.name)
                same_grid = tuple(variant.grid or scene.grid) == tuple(finest_grid)
                shared = same_grid and variant.dt_s is None
                ref = finest if shared else _run(scene, reference_for(variant), steps, out, pool)
                rec = _run(scene, variant, steps, out, pool)
                row, se = _row(scene, rec, ref, out, finest)
                rows.append(row)
                curves[(scene.name, variant.name)] = (np.asarray(rec.time_s), se)
                if on_row is not None:
                    on_row(row)
                bar.update()
    bar.close()
    rows = _mark_pareto(rows)
    write_outputs(rows, curves, out, steps=steps, command=command)
    return rows


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
