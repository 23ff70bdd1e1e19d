"""What the job queue stores and returns: jobs, their progress, log lines, heartbeats, reaps."""

from __future__ import annotations

import json
import sqlite3
from dataclasses import asdict, dataclass, field
from typing import Any

from diathermy.worker.specs import JobKind, JobState


@dataclass(frozen=True)
class JobProgress:
    """How far a job is: fraction done, samples/scenarios written, epoch and losses, ETA in s."""

    fraction: float = 0.0
    samples: int | None = None
    scenarios: int | None = None
    epoch: int | None = None
    epochs: int | None = None
    train_loss: float | None = None
    val_loss: float | None = None
    val_rel_l2: float | None = None
    eta_s: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {k: v for k, v in asdict(self).items() if v is not None}


@dataclass(frozen=True)
class Job:
    """One job as stored; ``spec`` and ``result`` are the JSON objects they were saved as."""

    id: str
    kind: JobKind
    state: JobState
    owner: str
    spec: dict[str, Any]
    depends_on: str | None
    progress: JobProgress
    result: dict[str, Any] | None
    error: str | None
    attempts: int
    max_attempts: int
    worker: str | None
    lease_expires: float | None
    cancel_requested: bool
    created_at: float
    started_at: float | None
    finished_at: float | None
    version: int


@dataclass(frozen=True)
class LogLine:
    seq: int
    ts: float
    line: str


@dataclass(frozen=True)
class Heartbeat:
    """A worker's lease renewal: whether it still owns the job, whether to cancel it, and
    whether its job process has already recorded the end."""

    owned: bool
    cancel: bool
    finished: bool = False


@dataclass(frozen=True)
class ReapReport:
    requeued: list[str] = field(default_factory=list)
    failed: list[str] = field(default_factory=list)
    cancelled: list[str] = field(default_factory=list)


def job_from_row(row: sqlite3.Row) -> Job:
    """A ``jobs`` table row as a Job."""
    progress = json.loads(row["progress"])
    return Job(
        id=row["id"],
        kind=JobKind(row["kind"]),
        state=JobState(row["state"]),
        owner=row["owner"],
        spec=json.loads(row["spec"]),
        depends_on=row["depends_on"],
        progress=JobProgress(**progress),
        result=json.loads(row["result"]) if row["result"] else None,
        error=row["error"],
        attempts=int(row["attempts"]),
        max_attempts=int(row["max_attempts"]),
        worker=row["worker"],
        lease_expires=row["lease_expires"],
        cancel_requested=bool(row["cancel_requested"]),
        created_at=float(row["created_at"]),
        started_at=row["started_at"],
        finished_at=row["finished_at"],
        version=int(row["version"]),
    )
