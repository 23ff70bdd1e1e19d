"""Service functions of the job and model routes: the queue and registry behind HTTP.

Keyword-only, return values, raise the service's exceptions; the routes do the HTTP.
"""

from __future__ import annotations

import asyncio
import functools
import json
import time
from collections.abc import AsyncIterator
from pathlib import Path

import anyio.to_thread

from diathermy.service.config import Settings
from diathermy.service.exceptions import (
    BadRequestError,
    LimitExceededError,
    NotFoundError,
    TooManyJobsError,
)
from diathermy.service.job_schemas import (
    JobList,
    JobLog,
    JobLogLine,
    JobProgressPublic,
    JobPublic,
    ModelList,
    ModelPublic,
)
from diathermy.worker.job_records import Job
from diathermy.worker.queue import JobNotFoundError, JobQueue
from diathermy.worker.registry import (
    ModelInfo,
    ModelNotFoundError,
    activate_model,
    active_models,
    get_model,
    list_models,
)
from diathermy.worker.specs import DatasetJobSpec, JobKind, JobState, TrainingJobSpec


def job_public(job: Job) -> JobPublic:
    return JobPublic(
        id=job.id,
        kind=job.kind,
        state=job.state,
        spec=job.spec,
        depends_on=job.depends_on,
        progress=JobProgressPublic(**job.progress.to_dict()),
        result=job.result,
        error=job.error,
        attempts=job.attempts,
        max_attempts=job.max_attempts,
        worker=job.worker,
        cancel_requested=job.cancel_requested,
        created_at=job.created_at,
        started_at=job.started_at,
        finished_at=job.finished_at,
    )


def _owned(queue: JobQueue, owner: str, job_id: str) -> Job:
    try:
        return queue.get(job_id, owner=owner)
    except JobNotFoundError as err:
        raise NotFoundError(str(err), field="job_id") from None


def submit_job(
    *,
    queue: JobQueue,
    settings: Settings,
    owner: str,
    spec: DatasetJobSpec | TrainingJobSpec,
) -> JobPublic:
    """Check limits and references, then queue the job."""
    active = queue.count_active(owner)
    if active >= settings.max_active_jobs_per_token:
        raise TooManyJobsError(
            f"this token already has {active} queued or running jobs, the limit is "
            f"{settings.max_active_jobs_per_token}; wait or cancel one"
        )
    depends_on = None
    if isinstance(spec, DatasetJobSpec):
        nz, ny, nx = spec.config.grid
        if nz * ny * nx > settings.max_grid_nodes:
            raise LimitExceededError(
                f"grid {nz}x{ny}x{nx} has {nz * ny * nx} nodes, over the limit of "
                f"{settings.max_grid_nodes}",
                field="config.grid",
            )
    else:
        try:
            dataset = queue.get(spec.dataset, owner=owner)
        except JobNotFoundError:
            raise BadRequestError(f"no dataset job {spec.dataset!r}", field="dataset") from None
        if dataset.kind is not JobKind.dataset:
            raise BadRequestError(f"job {spec.dataset} is not a dataset job", field="dataset")
        if dataset.state in (JobState.failed, JobState.cancelled):
            raise BadRequestError(
                f"dataset job {spec.dataset} ended {dataset.state.value}", field="dataset"
            )
        depends_on = dataset.id
    job = queue.submit(
        JobKind(spec.kind), spec.model_dump(mode="json"), owner=owner, depends_on=depends_on
    )
    return job_public(job)


def list_jobs(
    *, queue: JobQueue, owner: str, state: JobState | None, kind: JobKind | None
) -> JobList:
    jobs = queue.list_jobs(owner=owner, state=state)
    return JobList(jobs=[job_public(j) for j in jobs if kind is None or j.kind is kind])


def get_job(*, queue: JobQueue, owner: str, job_id: str) -> JobPublic:
    return job_public(_owned(queue, owner, job_id))


def cancel_job(*, queue: JobQueue, owner: str, job_id: str) -> JobPublic:
    try:
        return job_public(queue.cancel(job_id, owner=owner))
    except JobNotFoundError as err:
        raise NotFoundError(str(err), field="job_id") from None


def job_log(*, queue: JobQueue, owner: str, job_id: str, after: int) -> JobLog:
    _owned(queue, owner, job_id)
    lines = queue.logs(job_id, after=after)
    return JobLog(lines=[JobLogLine(seq=x.seq, ts=x.ts, line=x.line) for x in lines])


def _sse(event: str, data: str, event_id: int | None = None) -> bytes:
    head = f"id: {event_id}\n" if event_id is not None else ""
    return f"{head}event: {event}\ndata: {data}\n\n".encode()


async def job_events(
    *, queue: JobQueue, job_id: str, timeout_s: float, poll_s: float = 0.25
) -> AsyncIterator[bytes]:
    """Server-sent events: ``log`` per log line, ``progress`` per change, then ``end``."""
    version, seq = -1, 0
    deadline = time.monotonic() + timeout_s
    while True:
        job = await anyio.to_thread.run_sync(queue.get, job_id)
        lines = await anyio.to_thread.run_sync(functools.partial(queue.logs, job_id, after=seq))
        for line in lines:
            body = {"seq": line.seq, "ts": line.ts, "line": line.line}
            yield _sse("log", json.dumps(body), line.seq)
            seq = line.seq
        if job.version != version:
            version = job.version
            yield _sse("progress", job_public(job).model_dump_json())
        if job.state.terminal:
            yield _sse("end", job_public(job).model_dump_json())
            return
        if time.monotonic() > deadline:
            yield _sse("timeout", json.dumps({"after_s": timeout_s}))
            return
        await asyncio.sleep(poll_s)


def _model_public(info: ModelInfo, active: dict[str, str]) -> ModelPublic:
    return ModelPublic(**info.to_json(), ref=info.ref, active=info.ref in active.values())


def list_registered(*, data_dir: Path) -> ModelList:
    active = active_models(data_dir)
    return ModelList(
        models=[_model_public(m, active) for m in list_models(data_dir)], active=active
    )


def get_registered(*, data_dir: Path, name: str, version: int) -> ModelPublic:
    try:
        info = get_model(data_dir, f"{name}:{version}")
    except ModelNotFoundError:
        raise NotFoundError(f"no model {name}:{version}", field="name") from None
    return _model_public(info, active_models(data_dir))


def activate_registered(*, data_dir: Path, name: str, version: int) -> ModelPublic:
    try:
        info = activate_model(data_dir, f"{name}:{version}")
    except ModelNotFoundError:
        raise NotFoundError(f"no model {name}:{version}", field="name") from None
    return _model_public(info, active_models(data_dir))
