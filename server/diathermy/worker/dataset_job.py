"""A dataset job: ``datagen.generate`` into ``DATA_DIR/datasets/<id>.h5``, resumed on retry."""

from __future__ import annotations

import hashlib
import time
from typing import Any

from diathermy.datagen.config import DatagenConfig
from diathermy.datagen.generate import generate
from diathermy.worker.context import JobContext, eta_s
from diathermy.worker.job_records import JobProgress
from diathermy.worker.layout import dataset_path
from diathermy.worker.specs import DatasetJobSpec


def dataset_sha256(config: DatagenConfig) -> str:
    """The dataset's identity: sha256 of its generating config, seed included.

    The samples are a function of it (datagen makes them bit-identical across engines, worker
    counts and resumes), so it is cheap where hashing a large HDF5 file is not.
    """
    return hashlib.sha256(config.data_json().encode("utf-8")).hexdigest()


def run_dataset_job(ctx: JobContext) -> dict[str, Any]:
    """Generate (or finish) the job's dataset; returns the job result."""
    spec = DatasetJobSpec.model_validate(ctx.job.spec)
    config = spec.config
    out = dataset_path(ctx.data_dir, ctx.job.id)
    resume = out.exists()
    if resume:
        ctx.log(f"resuming {out.name}: committed scenarios are kept")
    t0 = time.monotonic()
    first: list[int] = []

    def on_commit(index: int) -> None:
        if not first:
            first.append(index)
        done = index + 1
        ctx.progress(
            JobProgress(
                fraction=done / config.n_scenarios,
                scenarios=done,
                samples=done * config.n_steps,
                eta_s=eta_s(time.monotonic() - t0, done - first[0], config.n_scenarios - first[0]),
            )
        )
        ctx.log(f"scenario {index} committed ({done}/{config.n_scenarios})")

    summary = generate(
        config,
        out,
        engine=spec.engine,
        workers=spec.workers,
        resume=resume,
        on_commit=on_commit,
        scheduler_address=spec.scheduler,
    )
    ctx.log(
        f"{summary.complete_scenarios} scenarios, {summary.samples} samples "
        f"({summary.computed_scenarios} computed this attempt) in {summary.wall_s:.1f} s"
    )
    return {
        "dataset_path": str(out),
        "grid": list(config.grid),
        "scenarios": summary.complete_scenarios,
        "samples": summary.samples,
        "dataset_sha256": dataset_sha256(config),
    }
