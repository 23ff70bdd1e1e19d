"""The worker: claims jobs, runs each in a forked job process, renews the lease, cancels.

The worker process itself stays light and responsive: it heartbeats the lease every
``heartbeat_s`` and reads the cancel flag at the same time, so a cancelled job's process gets
SIGTERM within a heartbeat and SIGKILL ``grace_s`` later if it has not stopped.
"""

from __future__ import annotations

import multiprocessing
import os
import secrets
import signal
import socket
import time
from pathlib import Path
from types import FrameType

from diathermy.worker.job_records import Job
from diathermy.worker.queue import JobQueue
from diathermy.worker.runner import job_function, run_job_process
from diathermy.worker.specs import JobState


def default_worker_id() -> str:
    return f"{socket.gethostname()}:{os.getpid()}:{secrets.token_hex(2)}"


class Worker:
    """Takes jobs from the queue in ``data_dir`` and runs them one at a time."""

    def __init__(
        self,
        data_dir: str | Path,
        *,
        poll_s: float = 1.0,
        lease_s: float = 30.0,
        heartbeat_s: float = 0.5,
        grace_s: float = 5.0,
        worker_id: str | None = None,
    ) -> None:
        if not lease_s > 2 * heartbeat_s:
            raise ValueError(f"lease_s ({lease_s}) must exceed twice heartbeat_s ({heartbeat_s})")
        self.queue = JobQueue(data_dir)
        self.poll_s = poll_s
        self.lease_s = lease_s
        self.heartbeat_s = heartbeat_s
        self.grace_s = grace_s
        self.id = worker_id or default_worker_id()
        self.stopping = False
        self._fork = multiprocessing.get_context("fork")

    def install_signal_handlers(self) -> None:
        """SIGTERM/SIGINT: stop taking jobs; the running one is requeued to resume elsewhere."""

        def stop(_signum: int, _frame: FrameType | None) -> None:
            self.stopping = True

        signal.signal(signal.SIGTERM, stop)
        signal.signal(signal.SIGINT, stop)

    def run(self, *, once: bool = False) -> int:
        """Run jobs until stopped (``once``: until no job is runnable); returns jobs run."""
        done = 0
        while not self.stopping:
            job = self.queue.claim(self.id, lease_s=self.lease_s)
            if job is None:
                if once:
                    break
                self._sleep(self.poll_s)
                continue
            self.run_job(job)
            done += 1
        return done

    def _sleep(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while not self.stopping and time.monotonic() < end:
            time.sleep(min(0.1, end - time.monotonic()))

    def run_job(self, job: Job) -> Job:
        """Run a job this worker has claimed, to its end; returns it as it ended."""
        job_function(job.kind)  # import in the worker, once: every job process forks with it
        proc = self._fork.Process(
            target=run_job_process, args=(str(self.queue.data_dir), job.id, self.id)
        )
        proc.start()
        reason, since, next_beat = "", 0.0, 0.0
        while proc.exitcode is None:
            proc.join(timeout=0.1)
            now = time.monotonic()
            if now >= next_beat and not reason:
                beat = self.queue.heartbeat(job.id, self.id, lease_s=self.lease_s)
                next_beat = now + self.heartbeat_s
                if not beat.finished:
                    reason = "lost" if not beat.owned else "cancel" if beat.cancel else ""
            if self.stopping and not reason:
                reason = "stop"
            if reason and not since:
                since = now
                self._signal(proc, signal.SIGTERM)
            if since and now - since > self.grace_s:
                self._signal(proc, signal.SIGKILL)
        self._signal(proc, signal.SIGKILL)  # its group: leftover scenario processes
        return self._settle(job, reason, proc.exitcode)

    @staticmethod
    def _signal(proc: multiprocessing.process.BaseProcess, sig: signal.Signals) -> None:
        """Signal the job process's group (or the process, before it has made its group)."""
        if proc.pid is None:
            return
        try:
            os.killpg(proc.pid, sig)
        except (ProcessLookupError, PermissionError):
            if proc.exitcode is None:
                os.kill(proc.pid, sig)

    def _settle(self, job: Job, reason: str, exitcode: int | None) -> Job:
        if reason == "cancel":
            self.queue.finish(job.id, self.id, JobState.cancelled)
        elif reason == "stop":
            self.queue.release(job.id, self.id, f"worker {self.id} stopped; the job will resume")
        elif reason == "lost":
            self.queue.append_log(job.id, f"worker {self.id} lost its lease and stopped the job")
        else:
            how = f"signal {-exitcode}" if exitcode is not None and exitcode < 0 else f"{exitcode}"
            self.queue.finish(
                job.id, self.id, JobState.failed, error=f"the job process exited ({how})"
            )  # a no-op when the job process recorded its own end
        return self.queue.get(job.id)
