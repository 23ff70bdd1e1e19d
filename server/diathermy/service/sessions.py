"""What the session routes do, as keyword-only functions that return values (no HTTP here).

Engine work runs in each session's engine process (``engine_process.py``), called from worker
threads under the session's lock, so a long step never blocks the event loop or other sessions. A step or restore on a session that is busy raises
``SessionBusyError`` at once (HTTP 409); reads wait for the lock.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import AsyncIterator, Callable
from typing import Any, TypeVar

import anyio.to_thread
import numpy as np

from diathermy.errors import SceneError
from diathermy.scene import builtin_scene, scene_from_dict
from diathermy.service import engine_ops as ops
from diathermy.service.config import Settings
from diathermy.service.engine_process import RemoteSim
from diathermy.service.exceptions import (
    EngineProcessError,
    SessionBusyError,
    SessionNotFoundError,
)
from diathermy.service.hub import Frame, Subscription, report_dict
from diathermy.service.limits import check_drive, check_grid, check_session_count, check_steps
from diathermy.service.metrics import ServiceMetrics
from diathermy.service.registry import Control, SessionRecord, SessionRegistry, public_meta
from diathermy.service.schemas import (
    ElectrodeUpdate,
    GridPublic,
    SessionCreate,
    SessionPublic,
    SnapshotPublic,
)

T = TypeVar("T")
log = logging.getLogger("diathermy.service.sessions")


async def run_locked(
    rec: SessionRecord,
    registry: SessionRegistry,
    fn: Callable[[Any], T],
    *,
    wait: bool = True,
) -> T:
    """Run ``fn(sim)`` in a worker thread under the session lock (loading the session first).

    ``wait=False`` marks a step or restore: a second one while the first is queued or running
    is refused with ``SessionBusyError`` (409); autosaves, reads and stream steps only delay it.
    """
    if rec.deleted:
        raise SessionNotFoundError(f"session {rec.id} was deleted", field="session_id")
    if not wait:
        if rec.exclusive:
            raise SessionBusyError(
                f"session {rec.id} is busy with another step or restore; retry when it is done"
            )
        rec.exclusive = True
    try:
        async with session_lock(rec):
            return await anyio.to_thread.run_sync(lambda: fn(registry.load(rec)))
    finally:
        if not wait:
            rec.exclusive = False


@contextlib.asynccontextmanager
async def session_lock(rec: SessionRecord) -> AsyncIterator[None]:
    """Hold the session lock; a stream's stepping batch yields it after the step in progress."""
    rec.waiting += 1
    rec.interrupt.set()
    counted = True
    try:
        async with rec.lock:
            rec.waiting -= 1
            counted = False
            yield
    finally:
        if counted:
            rec.waiting -= 1


async def create_session(
    *,
    registry: SessionRegistry,
    settings: Settings,
    metrics: ServiceMetrics,
    owner: str,
    body: SessionCreate,
) -> SessionRecord:
    """Validate limits, build the simulation off the event loop, register and checkpoint it."""
    check_session_count(settings, len(registry.owned(owner)))
    if body.builtin is not None:
        try:
            scene = builtin_scene(body.builtin)
        except SceneError as err:
            raise SceneError(f"builtin: {err}") from None
    else:
        assert body.scene is not None
        scene = body.scene
    if body.grid is not None:
        data = scene.model_dump()
        data["grid"] = body.grid
        data["resolution"] = None  # a uniform grid replaces a graded scene's resolution
        scene = scene_from_dict(data)
    check_grid(settings, scene.node_shape, scene.closed_effects)
    check_drive(scene)

    rec = await anyio.to_thread.run_sync(lambda: registry.create(owner=owner, scene=scene))
    log.info("created session", extra={"session": rec.id, "scene": scene.name})
    return rec


def session_public(rec: SessionRecord) -> SessionPublic:
    """The public view of a session, from its metadata (and the live simulation if loaded)."""
    m = public_meta(rec)
    return SessionPublic(
        id=rec.id,
        scene_name=m["scene_name"],
        grid=GridPublic(**m["grid"]),
        effects=m["effects"],
        dof_counts=m["dof_counts"],
        step=m["step"],
        time_s=m["time_s"],
        created_at=m["created_at"],
        loaded=rec.sim is not None,
        last_report=report_dict(rec.sim) if rec.sim is not None else None,
        snapshots=[SnapshotPublic(**s) for s in m.get("snapshots", [])],
    )


def advance(
    rec: SessionRecord,
    registry: SessionRegistry,
    sim: RemoteSim,
    n: int,
    metrics: ServiceMetrics,
) -> list[Any]:
    """Take ``n`` steps, journalling then publishing each (worker thread, under the lock)."""
    reports = []
    for _ in range(n):
        subs = rec.hub.subscriptions()
        rep, frames = sim.call(ops.step_frames, subs, rec.id, rec.control_id)
        publish_step(rec, registry, metrics, rep, frames)
        reports.append(rep)
    return reports


def publish_step(
    rec: SessionRecord,
    registry: SessionRegistry,
    metrics: ServiceMetrics,
    report: Any,
    frames: dict[Subscription, Frame],
) -> None:
    """Journal the step the engine just took, then hand its frames to the subscribers."""
    registry.log_step(rec)
    metrics.observe_report(report)
    drops = rec.hub.deliver(frames)
    if drops:
        metrics.frames_dropped.inc(drops)


def control_applied(
    rec: SessionRecord, registry: SessionRegistry, control: Control, result: tuple[int, int]
) -> tuple[int, int]:
    """Journal an electrode control the engine applied; (its control id, the step it applies
    after)."""
    registry.log_electrode(rec, control.name, control.changes)
    rec.control_id = max(rec.control_id, result[0])
    return result


async def step_session(
    *,
    registry: SessionRegistry,
    settings: Settings,
    metrics: ServiceMetrics,
    rec: SessionRecord,
    n: int,
) -> list[Any]:
    """Step a session ``n`` times; returns the step reports."""
    check_steps(settings, n)
    return await run_locked(
        rec, registry, lambda sim: advance(rec, registry, sim, n, metrics), wait=False
    )


async def update_electrode(
    *, registry: SessionRegistry, rec: SessionRecord, name: str, update: ElectrodeUpdate
) -> tuple[int, int]:
    """Apply electrode changes before the next step; returns (new control id, step applied at)."""

    control = Control(name, update.model_dump(exclude_none=True))

    def apply(sim: RemoteSim) -> tuple[int, int]:
        result = sim.call(ops.apply_control, control.name, control.changes, rec.control_id)
        return control_applied(rec, registry, control, result)

    if rec.deleted:
        raise SessionNotFoundError(f"session {rec.id} was deleted", field="session_id")
    offered = rec.offer(control)  # a stream is stepping: applied before its next step
    if offered is not None:
        result: tuple[int, int] = await offered
        return result
    return await run_locked(rec, registry, apply)


async def read_fields(
    *, registry: SessionRegistry, rec: SessionRecord, fields: str | None, dtype: str
) -> tuple[int, float, dict[str, np.ndarray]]:
    """(step, time, arrays) of the named fields, floats cast to ``dtype``."""

    result: tuple[int, float, dict[str, np.ndarray]] = await run_locked(
        rec, registry, lambda sim: sim.call(ops.read_fields, fields, dtype)
    )
    return result


async def read_surface(
    *, registry: SessionRegistry, rec: SessionRecord
) -> tuple[int, float, np.ndarray, np.ndarray]:
    """(step, time, vertices (n, 3) m, faces (m, 3)) of the cut surface."""

    result: tuple[int, float, np.ndarray, np.ndarray] = await run_locked(
        rec, registry, lambda sim: sim.call(ops.read_surface)
    )
    return result


async def vtu_bytes(*, registry: SessionRegistry, rec: SessionRecord) -> bytes:
    """The current state as a ParaView .vtu file."""

    data: bytes = await run_locked(rec, registry, lambda sim: sim.call(ops.vtu_bytes))
    return data


async def take_snapshot(*, registry: SessionRegistry, rec: SessionRecord) -> SnapshotPublic:
    """Write a named snapshot of the session's current state."""
    snap = await run_locked(rec, registry, lambda _sim: registry.snapshot(rec))
    return SnapshotPublic(**snap)


async def restore_snapshot(
    *, registry: SessionRegistry, rec: SessionRecord, snapshot_id: str
) -> SessionRecord:
    """Put the session back to a snapshot's state."""
    if not any(s["id"] == snapshot_id for s in rec.meta.get("snapshots", [])):
        raise SessionNotFoundError(f"no snapshot {snapshot_id!r}", field="snapshot_id")
    await run_locked(rec, registry, lambda _sim: registry.restore(rec, snapshot_id), wait=False)
    rec.control_id += 1
    return rec


async def delete_session(*, registry: SessionRegistry, rec: SessionRecord) -> None:
    """Remove a session from memory and disk; its stream clients get an error and a close."""
    rec.deleted = True  # refuses new work and ends a stepping batch
    async with session_lock(rec):
        await anyio.to_thread.run_sync(lambda: registry.remove(rec))
    if rec.driver is not None:
        await rec.driver.close_all(4404, "not_found", f"session {rec.id} was deleted", "session_id")


async def save_dirty(*, registry: SessionRegistry) -> int:
    """Checkpoint every loaded session that changed, compacting its journal (also while it is
    streamed: the stepping batch yields the lock after the step in progress)."""
    saved = 0
    for rec in list(registry.sessions.values()):
        if rec.sim is None or rec.sim.failed or not rec.dirty:
            continue  # a dead engine's session is on disk already: checkpoint plus journal
        async with session_lock(rec):
            if rec.id in registry.sessions and not rec.deleted:
                try:
                    await anyio.to_thread.run_sync(registry.save, rec)
                except EngineProcessError as err:  # nothing lost: the journal holds its steps
                    log.warning("not checkpointed", extra={"session": rec.id, "reason": str(err)})
                    continue
                saved += 1
    return saved
