"""The job queue: one SQLite file in the data directory, shared by the server and its workers.

WAL mode lets readers (the service) run beside one writer; every state change is a
``BEGIN IMMEDIATE`` transaction, so two workers claiming at once are serialised and never take
the same job. A running job holds a lease its worker renews by heartbeat; a lease that expires
(the worker died) is reaped by the next claim: the job is queued again to resume, or failed
with the reason once it has used its attempts. Every transition is written to the job's log.
"""

from __future__ import annotations

import contextlib
import json
import secrets
import sqlite3
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from diathermy.errors import DiathermyError
from diathermy.worker.job_records import (
    Heartbeat,
    Job,
    JobProgress,
    LogLine,
    ReapReport,
    job_from_row,
)
from diathermy.worker.specs import JobKind, JobState

DB_NAME = "jobs.sqlite"
DEFAULT_MAX_ATTEMPTS = 3

_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    kind TEXT NOT NULL,
    state TEXT NOT NULL,
    owner TEXT NOT NULL,
    spec TEXT NOT NULL,
    depends_on TEXT,
    progress TEXT NOT NULL DEFAULT '{}',
    result TEXT,
    error TEXT,
    attempts INTEGER NOT NULL DEFAULT 0,
    max_attempts INTEGER NOT NULL,
    worker TEXT,
    lease_expires REAL,
    cancel_requested INTEGER NOT NULL DEFAULT 0,
    created_at REAL NOT NULL,
    started_at REAL,
    finished_at REAL,
    version INTEGER NOT NULL DEFAULT 0
);
CREATE INDEX IF NOT EXISTS jobs_state ON jobs (state, created_at);
CREATE TABLE IF NOT EXISTS job_log (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    job_id TEXT NOT NULL,
    ts REAL NOT NULL,
    line TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS job_log_job ON job_log (job_id, seq);
"""


class JobNotFoundError(DiathermyError, LookupError):
    """No job with this id belongs to the caller."""


class JobQueue:
    """The queue in ``data_dir/jobs.sqlite``; a connection per operation, so it is fork-safe."""

    def __init__(self, data_dir: str | Path, *, busy_timeout_s: float = 30.0) -> None:
        self.data_dir = Path(data_dir).resolve()
        self.path = self.data_dir / DB_NAME
        self.busy_timeout_s = busy_timeout_s
        self.data_dir.mkdir(parents=True, exist_ok=True)
        with self._connect() as con:
            con.execute("PRAGMA journal_mode=WAL")
            con.executescript(_SCHEMA)

    @contextlib.contextmanager
    def _connect(self) -> Iterator[sqlite3.Connection]:
        con = sqlite3.connect(self.path, timeout=self.busy_timeout_s, isolation_level=None)
        con.row_factory = sqlite3.Row
        try:
            yield con
        finally:
            con.close()

    @contextlib.contextmanager
    def _write(self) -> Iterator[sqlite3.Connection]:
        """A ``BEGIN IMMEDIATE`` transaction: the write lock is taken before anything is read."""
        with self._connect() as con:
            con.execute("BEGIN IMMEDIATE")
            try:
                yield con
            except BaseException:
                con.execute("ROLLBACK")
                raise
            con.execute("COMMIT")

    @staticmethod
    def _log(con: sqlite3.Connection, job_id: str, line: str) -> None:
        con.execute(
            "INSERT INTO job_log (job_id, ts, line) VALUES (?, ?, ?)", (job_id, time.time(), line)
        )

    @staticmethod
    def _get(con: sqlite3.Connection, job_id: str) -> Job | None:
        row = con.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return job_from_row(row) if row is not None else None

    # -- clients ---------------------------------------------------------------------------

    def submit(
        self,
        kind: JobKind,
        spec: dict[str, Any],
        *,
        owner: str,
        depends_on: str | None = None,
        max_attempts: int = DEFAULT_MAX_ATTEMPTS,
    ) -> Job:
        """Queue a job; returns it (state queued)."""
        job_id = "j-" + secrets.token_hex(6)
        with self._write() as con:
            con.execute(
                "INSERT INTO jobs (id, kind, state, owner, spec, depends_on, max_attempts, "
                "created_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    job_id,
                    kind.value,
                    JobState.queued.value,
                    owner,
                    json.dumps(spec, sort_keys=True),
                    depends_on,
                    max_attempts,
                    time.time(),
                ),
            )
            self._log(con, job_id, f"queued ({kind.value})")
            job = self._get(con, job_id)
        assert job is not None
        return job

    def get(self, job_id: str, *, owner: str | None = None) -> Job:
        """A job by id (``owner`` given: only if it is theirs); ``JobNotFoundError`` otherwise."""
        with self._connect() as con:
            job = self._get(con, job_id)
        if job is None or (owner is not None and job.owner != owner):
            raise JobNotFoundError(f"no job {job_id!r}")
        return job

    def list_jobs(
        self, *, owner: str | None = None, state: JobState | None = None, limit: int = 1000
    ) -> list[Job]:
        """Jobs, newest first, optionally of one owner and one state."""
        sql, args = "SELECT * FROM jobs WHERE 1=1", list[str]()
        if owner is not None:
            sql, args = sql + " AND owner = ?", [*args, owner]
        if state is not None:
            sql, args = sql + " AND state = ?", [*args, state.value]
        with self._connect() as con:
            rows = con.execute(sql + " ORDER BY created_at DESC LIMIT ?", (*args, limit))
            return [job_from_row(r) for r in rows.fetchall()]

    def count_active(self, owner: str) -> int:
        """The owner's queued and running jobs."""
        with self._connect() as con:
            row = con.execute(
                "SELECT COUNT(*) FROM jobs WHERE owner = ? AND state IN ('queued', 'running')",
                (owner,),
            ).fetchone()
        return int(row[0])

    def cancel(self, job_id: str, *, owner: str | None = None) -> Job:
        """Cancel: a queued job at once, a running one by its worker within seconds."""
        with self._write() as con:
            job = self._get(con, job_id)
            if job is None or (owner is not None and job.owner != owner):
                raise JobNotFoundError(f"no job {job_id!r}")
            if job.state is JobState.queued:
                self._set_final(con, job_id, JobState.cancelled, None)
                self._log(con, job_id, "cancelled while queued")
            elif job.state is JobState.running and not job.cancel_requested:
                con.execute(
                    "UPDATE jobs SET cancel_requested = 1, version = version + 1 WHERE id = ?",
                    (job_id,),
                )
                self._log(con, job_id, "cancellation requested")
            job = self._get(con, job_id)
        assert job is not None
        return job

    def logs(self, job_id: str, *, after: int = 0, limit: int = 10_000) -> list[LogLine]:
        """Log lines of a job with ``seq > after``, oldest first."""
        with self._connect() as con:
            rows = con.execute(
                "SELECT seq, ts, line FROM job_log WHERE job_id = ? AND seq > ? ORDER BY seq "
                "LIMIT ?",
                (job_id, after, limit),
            ).fetchall()
        return [LogLine(int(r["seq"]), float(r["ts"]), r["line"]) for r in rows]

    # -- workers ---------------------------------------------------------------------------

    def claim(self, worker: str, *, lease_s: float) -> Job | None:
        """Reap expired leases, then take the oldest runnable queued job (or None)."""
        now = time.time()
        with self._write() as con:
            self._reap(con, now)
            rows = con.execute(
                "SELECT * FROM jobs WHERE state = 'queued' ORDER BY created_at, rowid"
            ).fetchall()
            for row in rows:
                job = job_from_row(row)
                if not self._dependency_ready(con, job):
                    continue
                con.execute(
                    "UPDATE jobs SET state = 'running', worker = ?, attempts = attempts + 1, "
                    "lease_expires = ?, started_at = COALESCE(started_at, ?), "
                    "version = version + 1 WHERE id = ?",
                    (worker, now + lease_s, now, job.id),
                )
                self._log(
                    con,
                    job.id,
                    f"attempt {job.attempts + 1} of {job.max_attempts} started by worker {worker}",
                )
                return self._get(con, job.id)
        return None

    def _dependency_ready(self, con: sqlite3.Connection, job: Job) -> bool:
        """True when the job can run; a job whose dependency ended badly is failed here."""
        if job.depends_on is None:
            return True
        dep = self._get(con, job.depends_on)
        if dep is not None and dep.state is JobState.succeeded:
            return True
        if dep is None or dep.state.terminal:
            why = "does not exist" if dep is None else f"ended {dep.state.value}"
            reason = f"dataset job {job.depends_on} {why}"
            self._set_final(con, job.id, JobState.failed, reason)
            self._log(con, job.id, f"failed: {reason}")
        return False

    def reap(self) -> ReapReport:
        """Requeue (or fail, when out of attempts) running jobs whose lease has expired."""
        with self._write() as con:
            return self._reap(con, time.time())

    def _reap(self, con: sqlite3.Connection, now: float) -> ReapReport:
        report = ReapReport()
        rows = con.execute(
            "SELECT * FROM jobs WHERE state = 'running' AND lease_expires < ?", (now,)
        ).fetchall()
        for row in rows:
            job = job_from_row(row)
            lost = f"worker {job.worker} stopped renewing its lease (died or was killed)"
            if job.cancel_requested:
                self._set_final(con, job.id, JobState.cancelled, None)
                self._log(con, job.id, f"cancelled: {lost}")
                report.cancelled.append(job.id)
            elif job.attempts < job.max_attempts:
                con.execute(
                    "UPDATE jobs SET state = 'queued', worker = NULL, lease_expires = NULL, "
                    "version = version + 1 WHERE id = ?",
                    (job.id,),
                )
                self._log(con, job.id, f"requeued to resume: {lost}")
                report.requeued.append(job.id)
            else:
                reason = f"{lost}; gave up after {job.attempts} attempts"
                self._set_final(con, job.id, JobState.failed, reason)
                self._log(con, job.id, f"failed: {reason}")
                report.failed.append(job.id)
        return report

    def heartbeat(self, job_id: str, worker: str, *, lease_s: float) -> Heartbeat:
        """Renew the lease of a job this worker runs; tells it whether to cancel."""
        with self._write() as con:
            cur = con.execute(
                "UPDATE jobs SET lease_expires = ? WHERE id = ? AND worker = ? AND "
                "state = 'running'",
                (time.time() + lease_s, job_id, worker),
            )
            job = self._get(con, job_id)
        finished = job is not None and job.state.terminal and job.worker == worker
        return Heartbeat(
            owned=cur.rowcount == 1,
            cancel=bool(job and job.cancel_requested),
            finished=finished,
        )

    def set_progress(self, job_id: str, worker: str, progress: JobProgress) -> None:
        """Store the progress of a running job (ignored if the worker no longer owns it)."""
        with self._write() as con:
            con.execute(
                "UPDATE jobs SET progress = ?, version = version + 1 WHERE id = ? AND "
                "worker = ? AND state = 'running'",
                (json.dumps(progress.to_dict()), job_id, worker),
            )

    def append_log(self, job_id: str, line: str) -> None:
        with self._write() as con:
            self._log(con, job_id, line)

    def finish(
        self,
        job_id: str,
        worker: str,
        state: JobState,
        *,
        error: str | None = None,
        result: dict[str, Any] | None = None,
    ) -> bool:
        """End a job this worker owns; False when it no longer does (lease lost)."""
        if not state.terminal:
            raise ValueError(f"finish needs a terminal state, got {state.value}")
        with self._write() as con:
            job = self._get(con, job_id)
            if job is None or job.state is not JobState.running or job.worker != worker:
                return False
            self._set_final(con, job_id, state, error, result)
            self._log(con, job_id, state.value + (f": {error}" if error else ""))
        return True

    def release(self, job_id: str, worker: str, reason: str) -> bool:
        """Give a running job back to the queue (the worker is stopping); it resumes later."""
        with self._write() as con:
            cur = con.execute(
                "UPDATE jobs SET state = 'queued', worker = NULL, lease_expires = NULL, "
                "attempts = MAX(attempts - 1, 0), version = version + 1 "
                "WHERE id = ? AND worker = ? AND state = 'running'",
                (job_id, worker),
            )
            if cur.rowcount == 1:
                self._log(con, job_id, f"requeued: {reason}")
        return cur.rowcount == 1

    @staticmethod
    def _set_final(
        con: sqlite3.Connection,
        job_id: str,
        state: JobState,
        error: str | None,
        result: dict[str, Any] | None = None,
    ) -> None:
        con.execute(
            "UPDATE jobs SET state = ?, error = ?, result = ?, finished_at = ?, "
            "lease_expires = NULL, version = version + 1 WHERE id = ?",
            (
                state.value,
                error,
                json.dumps(result) if result is not None else None,
                time.time(),
                job_id,
            ),
        )
