"""The accuracy-cost report: every variant of every scene against the FEM reference, side by side.

Each variant runs in its own process (so peak memory is its own), once: its record and fields are
kept in the output folder keyed by a hash of everything that decides the result, so an
interrupted report resumes where it stopped and a finished variant is never re-run.
"""

from __future__ import annotations

import multiprocessing as mp
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from tqdm import tqdm

from diathermy.errors import SceneError
from diathermy.physics.strain_energy import relative_strain_energy_error
from diathermy.report.measure import RunRecord, load_fields, run_variant
from diathermy.report.tables import Row, mark_pareto, write_outputs
from diathermy.report.variants import Variant, reference_for
from diathermy.scene import Scene


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
            interval_tolerance=rec.variant.interval_tolerance,
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
        interval_tolerance=rec.variant.interval_tolerance,
        dt_s=dt,
        guard=rec.variant.guard,
    ), se


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
    rows = mark_pareto(rows)
    write_outputs(rows, curves, out, steps=steps, command=command)
    return rows
