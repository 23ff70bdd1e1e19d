"""Jobs: submit dataset and training jobs, list, inspect, cancel, read the log, stream events."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Path, Query
from fastapi.responses import StreamingResponse

from diathermy.service import jobs as svc
from diathermy.service.deps import JobsDep, OwnerDep, StateDep
from diathermy.service.errors import ErrorResponses
from diathermy.service.job_schemas import JobList, JobLog, JobPublic
from diathermy.worker.specs import JobKind, JobSpec, JobState

router = APIRouter(prefix="/v1/jobs", tags=["jobs"], responses=ErrorResponses)
JobId = Annotated[str, Path(max_length=64, description="the job id")]


@router.post("", status_code=201, response_model=JobPublic, operation_id="submit_job")
def submit_job(
    spec: Annotated[JobSpec, Body()], state: StateDep, queue: JobsDep, owner: OwnerDep
) -> Any:
    """Queue a dataset job (a datagen config) or a training job (on a dataset job's output)."""
    return svc.submit_job(queue=queue, settings=state.settings, owner=owner, spec=spec)


@router.get("", response_model=JobList, operation_id="list_jobs")
def list_jobs(
    queue: JobsDep,
    owner: OwnerDep,
    state: JobState | None = None,
    kind: JobKind | None = None,
) -> Any:
    """The caller's jobs, newest first."""
    return svc.list_jobs(queue=queue, owner=owner, state=state, kind=kind)


@router.get("/{job_id}", response_model=JobPublic, operation_id="get_job")
def get_job(job_id: JobId, queue: JobsDep, owner: OwnerDep) -> Any:
    """One job: state, progress (fraction, samples, epoch, losses, ETA), result or error."""
    return svc.get_job(queue=queue, owner=owner, job_id=job_id)


@router.post("/{job_id}/cancel", response_model=JobPublic, operation_id="cancel_job")
def cancel_job(job_id: JobId, queue: JobsDep, owner: OwnerDep) -> Any:
    """Cancel: a queued job at once, a running one within seconds (its worker stops it)."""
    return svc.cancel_job(queue=queue, owner=owner, job_id=job_id)


@router.get("/{job_id}/log", response_model=JobLog, operation_id="get_job_log")
def get_job_log(
    job_id: JobId,
    queue: JobsDep,
    owner: OwnerDep,
    after: Annotated[int, Query(ge=0, description="only lines with seq > after")] = 0,
) -> Any:
    """The job's log: every transition, attempt, committed scenario and epoch."""
    return svc.job_log(queue=queue, owner=owner, job_id=job_id, after=after)


@router.get(
    "/{job_id}/events",
    operation_id="job_events",
    response_class=StreamingResponse,
    responses={200: {"content": {"text/event-stream": {}}, "description": "SSE stream"}},
)
def job_events(
    job_id: JobId,
    queue: JobsDep,
    owner: OwnerDep,
    timeout_s: Annotated[float, Query(gt=0, le=3600, description="close after this long")] = 600,
) -> StreamingResponse:
    """Server-sent events: ``log`` lines, ``progress`` (the job) on change, ``end`` at the end."""
    svc.get_job(queue=queue, owner=owner, job_id=job_id)  # 404 before the stream starts
    return StreamingResponse(
        svc.job_events(queue=queue, job_id=job_id, timeout_s=timeout_s),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"},
    )
