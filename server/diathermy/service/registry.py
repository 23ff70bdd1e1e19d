"""Sessions in memory and on disk: ids, owners, locks, checkpoints and their metadata.

Layout of the data directory::

    sessions/<id>/meta.json          owner (token sha256), scene name, grid, step, time, snapshots
    sessions/<id>/state.h5           the latest checkpoint (restored after a restart)
    sessions/<id>/journal.jsonl      the commands since that checkpoint (``journal.py``)
    sessions/<id>/snapshots/<s>.h5   snapshots a client asked for (ids chosen by the server)

The checkpoint plus the journal is the session: ``meta.json``'s step and time are those of the
checkpoint, and a scan after a restart reads the journal to list the step a load will reach.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import shutil
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from diathermy.errors import CheckpointError
from diathermy.scene import Scene
from diathermy.service import engine_ops as ops
from diathermy.service.engine import EngineAdapter
from diathermy.service.engine_process import RemoteSim
from diathermy.service.exceptions import SessionNotFoundError
from diathermy.service.hub import StreamHub
from diathermy.service.journal import Journal, checkpoint_seq, last_step, mark_checkpoint, replay

log = logging.getLogger("diathermy.service.registry")


def _write_json_atomic(path: Path, data: dict[str, Any]) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=1), encoding="utf-8")
    os.replace(tmp, path)


def public_meta(rec: SessionRecord) -> dict[str, Any]:
    """The metadata with the live simulation's step, time and DOF counts (no engine call)."""
    if rec.sim is None:
        return dict(rec.meta)
    live = {"step": rec.sim.step_index, "time_s": rec.sim.time_s}
    return {**rec.meta, **live, "dof_counts": rec.sim.dof_counts or rec.meta.get("dof_counts")}


@dataclass(frozen=True)
class Control:
    """An electrode change asked for by a client: the electrode's name and the new values."""

    name: str
    changes: dict[str, Any]


@dataclass(eq=False)
class SessionRecord:
    """One session: its owner, metadata, the simulation once loaded, and what guards it."""

    id: str
    owner: str
    directory: Path
    meta: dict[str, Any]
    sim: RemoteSim | None = None  # the engine process, once loaded
    lock: asyncio.Lock = field(default_factory=asyncio.Lock)
    hub: StreamHub = field(default_factory=StreamHub)
    control_id: int = 0
    dirty: bool = False
    driver: Any = None  # the stream driver (stream.SessionDriver) while clients are connected
    journal: Journal | None = None
    deleted: bool = False
    waiting: int = 0  # tasks waiting for the lock: a stepping batch yields to them
    exclusive: bool = False  # a REST step or restore is queued or running (a second gets 409)
    batch_active: bool = False  # a stream's stepping batch holds the lock (driver.py)
    controls: dict[int, tuple[Control, asyncio.Future[Any]]] = field(default_factory=dict)
    batch_lock: threading.Lock = field(default_factory=threading.Lock)
    interrupt: threading.Event = field(default_factory=threading.Event)

    @property
    def state_path(self) -> Path:
        return self.directory / "state.h5"

    @property
    def meta_path(self) -> Path:
        return self.directory / "meta.json"

    def snapshot_path(self, snapshot_id: str) -> Path:
        return self.directory / "snapshots" / f"{snapshot_id}.h5"

    @property
    def journal_path(self) -> Path:
        return self.directory / "journal.jsonl"

    def offer(self, control: Control) -> asyncio.Future[Any] | None:
        """Send ``control`` to the engine while a stream's stepping batch runs: the engine
        applies it before its next step, and the batch journals it in the engine's order and
        settles the future with (control id, step applied after). None when no batch runs (then
        take the lock instead)."""
        with self.batch_lock:
            if not self.batch_active or self.sim is None:
                return None
            fut = asyncio.get_running_loop().create_future()
            rid = self.sim.submit(
                ops.apply_control, control.name, control.changes, self.control_id, urgent=True
            )
            self.controls[rid] = (control, fut)
        self.interrupt.set()
        return fut

    def write_meta(self) -> None:
        _write_json_atomic(self.meta_path, self.meta)


class SessionRegistry:
    """All sessions, keyed by id; lookups are by (owner, id) so other owners see nothing."""

    def __init__(
        self,
        data_dir: Path,
        engine: EngineAdapter,
        *,
        fsync: bool = False,
        engine_cpus: list[int] | None = None,
    ) -> None:
        self.root = Path(data_dir) / "sessions"
        self.engine = engine
        self.fsync = fsync
        self.engine_cpus = list(engine_cpus or [])  # each engine process runs on these
        self.sessions: dict[str, SessionRecord] = {}

    def scan(self) -> int:
        """Register every session found on disk (not loaded until first use); returns the count."""
        self.root.mkdir(parents=True, exist_ok=True)
        for meta_path in sorted(self.root.glob("*/meta.json")):
            try:
                meta = json.loads(meta_path.read_text(encoding="utf-8"))
                sid, owner = str(meta["id"]), str(meta["owner"])
            except (OSError, ValueError, KeyError) as err:
                log.error("skipping unreadable session %s: %s", meta_path.parent.name, err)
                continue
            if not (meta_path.parent / "state.h5").exists():
                log.error("skipping session %s: it has no checkpoint", sid)
                continue
            rec = SessionRecord(id=sid, owner=owner, directory=meta_path.parent, meta=meta)
            try:
                seq, step, time_s = checkpoint_seq(rec.state_path)
                recent = last_step(Journal(rec.journal_path).entries(after=seq))
            except CheckpointError as err:  # listed all the same; loading it answers 409
                log.error("session %s: %s", sid, err)
            else:
                meta["step"], meta["time_s"] = recent or (step, time_s)
            self.sessions[sid] = rec
        return len(self.sessions)

    def owned(self, owner: str) -> list[SessionRecord]:
        return [r for r in self.sessions.values() if r.owner == owner]

    def get(self, owner: str, session_id: str) -> SessionRecord:
        rec = self.sessions.get(session_id)
        if rec is None or rec.owner != owner:
            raise SessionNotFoundError(f"no session {session_id!r}", field="session_id")
        return rec

    def create(self, *, owner: str, scene: Scene) -> SessionRecord:
        """Build a simulation of ``scene`` in a new engine process, register and checkpoint it
        (worker thread)."""
        sid = uuid.uuid4().hex[:16]
        sim = RemoteSim(sid, cpus=self.engine_cpus)
        try:
            sim.call(ops.create, self.engine, scene)
            directory = self.root / sid
            (directory / "snapshots").mkdir(parents=True)
            meta = {"id": sid, "owner": owner, "created_at": time.time(), "snapshots": []}
            rec = SessionRecord(id=sid, owner=owner, directory=directory, meta=meta, sim=sim)
            self.save(rec)
        except BaseException:
            sim.close()
            raise
        self.sessions[sid] = rec
        return rec

    def load(self, rec: SessionRecord) -> RemoteSim:
        """The session's engine: its checkpoint loaded in a new engine process and the journal
        replayed there (worker thread, under the session lock). An engine process that ended is
        replaced the same way."""
        if rec.deleted:
            raise SessionNotFoundError(f"session {rec.id} was deleted", field="session_id")
        if rec.sim is not None and rec.sim.failed:
            rec.sim.close()
            rec.sim = None
        if rec.sim is None:
            t0 = time.perf_counter()
            seq, _, _ = checkpoint_seq(rec.state_path)
            journal = Journal(rec.journal_path, seq=seq, fsync=self.fsync)
            entries = journal.entries(after=seq)
            sim = RemoteSim(rec.id, cpus=self.engine_cpus)
            try:
                sim.call(ops.load, self.engine, rec.state_path)
                steps = sim.call(replay, entries)
            except BaseException:
                sim.close()
                raise
            if journal.torn:  # rewrite without the cut-short line before appending after it
                journal.compact(seq)
            journal.seq = max([seq, *(int(e["seq"]) for e in entries)])
            rec.sim, rec.journal = sim, journal
            rec.dirty = bool(entries)  # the next autosave folds the journal into a checkpoint
            log.info(
                "restored session",
                extra={
                    "session": rec.id,
                    "journal_entries": len(entries),
                    "replayed_steps": steps,
                    "seconds": round(time.perf_counter() - t0, 3),
                },
            )
        return rec.sim

    def log_step(self, rec: SessionRecord) -> None:
        """Journal the step just taken, before anything acknowledges it (worker thread)."""
        assert rec.journal is not None and rec.sim is not None
        rec.journal.append("step", step=rec.sim.step_index, time_s=rec.sim.time_s)
        rec.dirty = True

    def log_electrode(self, rec: SessionRecord, name: str, update: dict[str, Any]) -> None:
        """Journal an electrode change just applied, before it is acknowledged (worker thread)."""
        assert rec.journal is not None
        rec.journal.append("electrode", name=name, update=update)
        rec.dirty = True

    def save(self, rec: SessionRecord) -> None:
        """Checkpoint the session, then empty its journal (worker thread, under the session lock).

        Order matters for a crash at any point: the checkpoint (marked with the journal's
        sequence number) replaces the old one atomically, then the metadata, then the journal is
        compacted; entries the new checkpoint already holds are skipped by their number.
        """
        assert rec.sim is not None
        if rec.journal is None:
            rec.journal = Journal(rec.journal_path, fsync=self.fsync)
        seq = rec.journal.seq
        tmp = rec.state_path.with_suffix(".h5.tmp")
        rec.sim.call(ops.save_checkpoint, tmp)
        mark_checkpoint(tmp, seq)
        os.replace(tmp, rec.state_path)
        rec.meta.update(rec.sim.call(ops.sim_meta))
        rec.meta["saved_at"] = time.time()
        rec.write_meta()
        rec.journal.compact(seq)
        rec.dirty = False

    def snapshot(self, rec: SessionRecord) -> dict[str, Any]:
        """Write a named snapshot of the current state (worker thread, under the session lock)."""
        assert rec.sim is not None
        snap_id = uuid.uuid4().hex[:12]
        snap: dict[str, Any] = {
            "id": snap_id,
            "step": rec.sim.step_index,
            "time_s": rec.sim.time_s,
            "created_at": time.time(),
        }
        rec.sim.call(ops.save_checkpoint, rec.snapshot_path(snap_id))
        rec.meta.setdefault("snapshots", []).append(snap)
        rec.write_meta()
        return snap

    def restore(self, rec: SessionRecord, snapshot_id: str) -> None:
        """Replace the session's state by a snapshot's (worker thread, under the session lock)."""
        path = rec.snapshot_path(snapshot_id)
        if not path.exists():
            raise SessionNotFoundError(f"no snapshot {snapshot_id!r}", field="snapshot_id")
        assert rec.sim is not None
        rec.sim.call(ops.restore, self.engine, path, snapshot_id)
        self.save(rec)

    def remove(self, rec: SessionRecord) -> None:
        """Forget a session, end its engine process and delete its files."""
        rec.deleted = True
        self.sessions.pop(rec.id, None)
        self.unload(rec)
        shutil.rmtree(rec.directory, ignore_errors=True)

    def close_all(self) -> None:
        """End every engine process (shutdown, after the last checkpoints)."""
        for rec in list(self.sessions.values()):
            self.unload(rec)

    def unload(self, rec: SessionRecord) -> None:
        """End the session's engine process, if any (under the session lock, or at shutdown)."""
        sim, rec.sim = rec.sim, None
        if sim is not None:
            sim.close()
