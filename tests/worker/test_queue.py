"""The SQLite job queue: exclusive claims, leases, reaping, cancellation, dependencies."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from diathermy.worker.job_records import JobProgress
from diathermy.worker.queue import JobNotFoundError, JobQueue
from diathermy.worker.specs import JobKind, JobState

SPEC = {"kind": "dataset", "config": {"grid": [5, 5, 9], "n_scenarios": 2, "n_steps": 2}}


def test_concurrent_claims_take_each_job_once(tmp_path: Path) -> None:
    queue = JobQueue(tmp_path)
    ids = {queue.submit(JobKind.dataset, SPEC, owner="o").id for _ in range(30)}
    taken: list[tuple[str, str]] = []
    lock = threading.Lock()

    def claimer(name: str) -> None:
        q = JobQueue(tmp_path)  # its own connections, like a separate worker
        while (job := q.claim(name, lease_s=60)) is not None:
            with lock:
                taken.append((job.id, name))

    threads = [threading.Thread(target=claimer, args=(f"w{i}",)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(j for j, _ in taken) == sorted(ids)  # every job once, none twice
    assert all(queue.get(j).attempts == 1 for j in ids)


def test_expired_lease_requeues_then_fails_with_reason(tmp_path: Path) -> None:
    queue = JobQueue(tmp_path)
    job = queue.submit(JobKind.dataset, SPEC, owner="o", max_attempts=2)
    assert queue.claim("dead-1", lease_s=0.01).id == job.id
    time.sleep(0.05)
    again = queue.claim("alive", lease_s=0.01)  # reaps the expired lease, then takes the job
    assert again is not None and again.id == job.id and again.attempts == 2
    assert not queue.heartbeat(job.id, "dead-1", lease_s=10).owned  # the dead worker is fenced
    time.sleep(0.05)
    assert queue.claim("third", lease_s=10) is None
    failed = queue.get(job.id)
    assert failed.state is JobState.failed
    assert "stopped renewing its lease" in (failed.error or "") and "2 attempts" in failed.error
    lines = [x.line for x in queue.logs(job.id)]
    assert any(line.startswith("requeued to resume") for line in lines)


def test_heartbeat_keeps_the_lease_and_reports_cancel(tmp_path: Path) -> None:
    queue = JobQueue(tmp_path)
    job = queue.submit(JobKind.dataset, SPEC, owner="o")
    queue.claim("w", lease_s=0.2)
    for _ in range(3):
        time.sleep(0.1)
        beat = queue.heartbeat(job.id, "w", lease_s=0.2)
        assert beat.owned and not beat.cancel
    assert queue.reap().requeued == []
    queue.cancel(job.id, owner="o")
    assert queue.heartbeat(job.id, "w", lease_s=0.2).cancel
    assert queue.finish(job.id, "w", JobState.cancelled)
    assert queue.get(job.id).state is JobState.cancelled


def test_cancel_queued_is_immediate_and_owner_scoped(tmp_path: Path) -> None:
    queue = JobQueue(tmp_path)
    job = queue.submit(JobKind.dataset, SPEC, owner="alice")
    with pytest.raises(JobNotFoundError):
        queue.cancel(job.id, owner="bob")
    assert queue.cancel(job.id, owner="alice").state is JobState.cancelled
    assert queue.claim("w", lease_s=10) is None


def test_dependent_job_waits_then_fails_when_its_dataset_fails(tmp_path: Path) -> None:
    queue = JobQueue(tmp_path)
    data = queue.submit(JobKind.dataset, SPEC, owner="o")
    train = queue.submit(JobKind.training, {"kind": "training"}, owner="o", depends_on=data.id)
    assert queue.claim("w", lease_s=10).id == data.id
    assert queue.claim("w2", lease_s=10) is None  # training waits for its dataset
    queue.finish(data.id, "w", JobState.failed, error="boom")
    assert queue.claim("w2", lease_s=10) is None
    failed = queue.get(train.id)
    assert failed.state is JobState.failed and f"dataset job {data.id} ended failed" in failed.error


def test_only_the_owner_worker_sets_progress_and_finishes(tmp_path: Path) -> None:
    queue = JobQueue(tmp_path)
    job = queue.submit(JobKind.dataset, SPEC, owner="o")
    queue.claim("w", lease_s=10)
    queue.set_progress(job.id, "intruder", JobProgress(fraction=0.9))
    queue.set_progress(job.id, "w", JobProgress(fraction=0.5, samples=2))
    assert not queue.finish(job.id, "intruder", JobState.succeeded)
    got = queue.get(job.id)
    assert got.progress == JobProgress(fraction=0.5, samples=2) and got.state is JobState.running
    assert queue.finish(job.id, "w", JobState.succeeded, result={"ok": 1})
    assert queue.get(job.id).result == {"ok": 1}
