"""Request and response models of the job and model routes (the ``JobPublic`` family)."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, Field

from diathermy.worker.specs import JobKind, JobState


class JobProgressPublic(BaseModel):
    """How far a job is; fields that do not apply to its kind are absent."""

    fraction: float = Field(0.0, description="0..1")
    samples: int | None = Field(None, description="dataset samples committed")
    scenarios: int | None = Field(None, description="dataset scenarios committed")
    epoch: int | None = Field(None, description="training epochs done")
    epochs: int | None = None
    train_loss: float | None = None
    val_loss: float | None = None
    val_rel_l2: float | None = None
    eta_s: float | None = Field(None, description="estimated seconds left")


class JobPublic(BaseModel):
    """A job as its owner sees it."""

    id: str
    kind: JobKind
    state: JobState
    spec: dict[str, Any]
    depends_on: str | None = None
    progress: JobProgressPublic
    result: dict[str, Any] | None = None
    error: str | None = Field(None, description="why the job failed")
    attempts: int = Field(description="times a worker started it (a resumed job counts twice)")
    max_attempts: int
    worker: str | None = Field(None, description="the worker running (or that last ran) it")
    cancel_requested: bool = False
    created_at: float
    started_at: float | None = None
    finished_at: float | None = None


class JobList(BaseModel):
    jobs: list[JobPublic]


class JobLogLine(BaseModel):
    seq: int
    ts: float
    line: str


class JobLog(BaseModel):
    lines: list[JobLogLine]


class ModelPublic(BaseModel):
    """A registered model: what it was trained on, how it did, whether sessions use it."""

    name: str
    version: int
    ref: str = Field(description="name:version")
    grid: tuple[int, int, int] = Field(description="nodes (nz, ny, nx) it was trained for")
    architecture: dict[str, Any]
    dataset_sha256: str = Field(description="sha256 of the dataset's generating config and seed")
    dataset: dict[str, Any]
    metrics: dict[str, Any]
    training: dict[str, Any]
    created_at: float
    job_id: str | None = None
    active: bool = Field(description="sessions on its grid use it unless a scene names a model")


class ModelList(BaseModel):
    models: list[ModelPublic]
    active: dict[str, str] = Field(description="grid NZxNYxNX -> active name:version")
