"""What a running job sees of the queue: its spec, a progress setter and its log."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

from diathermy.worker.job_records import Job, JobProgress
from diathermy.worker.queue import JobQueue


class JobInterrupted(BaseException):
    """Raised in a job process by SIGTERM: unwind (committed work is kept) and exit."""


@dataclass
class JobContext:
    """The running job, the queue it came from and the worker that owns it."""

    queue: JobQueue
    job: Job
    worker: str
    started: float = field(default_factory=time.monotonic)

    @property
    def data_dir(self) -> Path:
        return self.queue.data_dir

    def log(self, line: str) -> None:
        self.queue.append_log(self.job.id, line)

    def progress(self, progress: JobProgress) -> None:
        self.queue.set_progress(self.job.id, self.worker, progress)


def eta_s(elapsed_s: float, done: float, total: float) -> float | None:
    """Remaining seconds at the rate so far (``done`` units in ``elapsed_s``), None before any."""
    if done <= 0 or total <= done:
        return None if done <= 0 else 0.0
    return elapsed_s / done * (total - done)
