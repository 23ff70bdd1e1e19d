"""Where the worker keeps things inside the data directory."""

from __future__ import annotations

from pathlib import Path


def dataset_path(data_dir: str | Path, job_id: str) -> Path:
    """The HDF5 dataset a dataset job writes: ``DATA_DIR/datasets/<job id>.h5``."""
    return Path(data_dir) / "datasets" / f"{job_id}.h5"


def job_dir(data_dir: str | Path, job_id: str) -> Path:
    """A job's scratch folder (training checkpoints): ``DATA_DIR/jobs/<job id>/``."""
    return Path(data_dir) / "jobs" / job_id
