"""The job process: runs one claimed job and records how it ended.

Forked by the worker (so the heavy imports the worker made are shared), in its own process
group. SIGTERM (cancel, worker stopping) unwinds the job, keeping what was committed; a
watchdog ends the group if the worker dies, so a killed worker leaves no orphan running the job.
"""

from __future__ import annotations

import importlib
import os
import signal
import threading
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any

from diathermy.worker.context import JobContext, JobInterrupted
from diathermy.worker.queue import JobQueue
from diathermy.worker.specs import JobKind, JobState

JOB_MODULES = {
    JobKind.dataset: ("diathermy.worker.dataset_job", "run_dataset_job"),
    JobKind.training: ("diathermy.worker.training_job", "run_training_job"),
}


def job_function(kind: JobKind) -> Callable[[JobContext], dict[str, Any]]:
    """The function that runs jobs of ``kind`` (importing it is the heavy part: torch, FEM)."""
    module, name = JOB_MODULES[kind]
    return getattr(importlib.import_module(module), name)


def _interrupt(_signum: int, _frame: FrameType | None) -> None:
    raise JobInterrupted


def _watch_parent(parent: int, period_s: float = 0.5) -> None:
    while os.getppid() == parent:
        time.sleep(period_s)
    os.killpg(os.getpgid(0), signal.SIGKILL)  # the worker is gone: so are we, and our pool


def run_job_process(data_dir: str, job_id: str, worker: str) -> None:
    """Entry point of the forked job process."""
    os.setpgid(0, 0)
    signal.signal(signal.SIGTERM, _interrupt)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the worker, which decides
    threading.Thread(target=_watch_parent, args=(os.getppid(),), daemon=True).start()
    queue = JobQueue(Path(data_dir))
    ctx = JobContext(queue=queue, job=queue.get(job_id), worker=worker)
    try:
        result = job_function(ctx.job.kind)(ctx)
    except JobInterrupted:
        ctx.log("job process interrupted; committed work is kept")
        return
    except Exception as err:
        for line in traceback.format_exc().rstrip().splitlines():
            ctx.log(line)
        queue.finish(job_id, worker, JobState.failed, error=f"{type(err).__name__}: {err}")
        return
    queue.finish(job_id, worker, JobState.succeeded, result=result)
