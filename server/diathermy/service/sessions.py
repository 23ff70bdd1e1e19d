"""What the session routes do, as keyword-only functions that return values (no HTTP here).

Engine work runs in worker threads under the session's lock, so a long step never blocks the
event loop or other sessions. A step or restore on a session that is busy raises
``SessionBusyError`` at once (HTTP 409); reads wait for the lock.
"""

from __future__ import annotations

import contextlib
import logging
import tempfile
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any, TypeVar

import anyio.to_thread
import numpy as np

from diathermy.errors import SceneError
from diathermy.scene import builtin_scene, scene_from_dict
from diathermy.service.config import Settings
from diathermy.service.exceptions import (
    BadRequestError,
    NotFoundError,
    SessionBusyError,
    SessionNotFoundError,
)
from diathermy.service.hub import report_dict
from diathermy.service.limits import check_drive, check_grid, check_session_count, check_steps
from diathermy.service.metrics import ServiceMetrics
from diathermy.service.registry import SessionRecord, SessionRegistry, public_meta
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

    def build() -> SessionRecord:
        sim = registry.engine.create(scene)
        return registry.add(owner=owner, sim=sim)

    rec = await anyio.to_thread.run_sync(build)
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
    rec: SessionRecord, registry: SessionRegistry, sim: Any, n: int, metrics: ServiceMetrics
) -> list[Any]:
    """Take ``n`` steps, journalling then publishing each (engine thread, under the lock)."""
    reports = []
    for _ in range(n):
        rep = sim.step()
        registry.log_step(rec)
        metrics.observe_report(rep)
        drops = rec.hub.publish(sim, session_id=rec.id, control_id=rec.control_id)
        if drops:
            metrics.frames_dropped.inc(drops)
        reports.append(rep)
    return reports


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

    def apply(sim: Any) -> tuple[int, int]:
        names = [e.name for e in sim.scene.electrodes]
        if name not in names:
            raise NotFoundError(
                f"unknown electrode {name!r}; electrodes: {', '.join(names)}", field="name"
            )
        changes = update.model_dump(exclude_none=True)
        sim.set_electrode(name, **changes)
        registry.log_electrode(rec, name, changes)
        rec.control_id += 1
        return rec.control_id, int(sim.step_index)

    if rec.deleted:
        raise SessionNotFoundError(f"session {rec.id} was deleted", field="session_id")
    offered = rec.offer(apply)  # a stream is stepping: applied between two of its steps
    if offered is not None:
        result: tuple[int, int] = await offered
        return result
    return await run_locked(rec, registry, apply)


def parse_field_names(text: str | None, available: list[str]) -> list[str]:
    """``a,b,c`` -> names, each checked against the session's fields."""
    names = [n.strip() for n in (text or "").split(",") if n.strip()]
    if not names:
        raise BadRequestError(
            f"name at least one field; available: {', '.join(available)}", field="fields"
        )
    unknown = [n for n in names if n not in available]
    if unknown:
        raise BadRequestError(
            f"unknown field(s) {', '.join(unknown)}; available: {', '.join(available)}",
            field="fields",
        )
    return list(dict.fromkeys(names))


async def read_fields(
    *, registry: SessionRegistry, rec: SessionRecord, fields: str | None, dtype: str
) -> tuple[int, float, dict[str, np.ndarray]]:
    """(step, time, arrays) of the named fields, floats cast to ``dtype``."""

    def read(sim: Any) -> tuple[int, float, dict[str, np.ndarray]]:
        names = parse_field_names(fields, list(sim.field_names()))
        arrays = {n: np.asarray(sim.field(n)) for n in names}
        with np.errstate(over="ignore"):
            arrays = {n: a.astype(dtype) if a.dtype.kind == "f" else a for n, a in arrays.items()}
        return int(sim.step_index), float(sim.time_s), arrays

    return await run_locked(rec, registry, read)


async def read_surface(
    *, registry: SessionRegistry, rec: SessionRecord
) -> tuple[int, float, np.ndarray, np.ndarray]:
    """(step, time, vertices (n, 3) m, faces (m, 3)) of the cut surface."""

    def read(sim: Any) -> tuple[int, float, np.ndarray, np.ndarray]:
        verts, faces = sim.cut_surface()
        return (
            int(sim.step_index),
            float(sim.time_s),
            np.asarray(verts, dtype=float).reshape(-1, 3),
            np.asarray(faces, dtype=np.int64).reshape(-1, 3),
        )

    return await run_locked(rec, registry, read)


async def vtu_bytes(*, registry: SessionRegistry, rec: SessionRecord) -> bytes:
    """The current state as a ParaView .vtu file."""

    def write(sim: Any) -> bytes:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "state.vtu"
            sim.write_vtu(path)
            return path.read_bytes()

    return await run_locked(rec, registry, write)


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
        if rec.sim is None or not rec.dirty:
            continue
        async with session_lock(rec):
            if rec.id in registry.sessions and not rec.deleted:
                await anyio.to_thread.run_sync(registry.save, rec)
                saved += 1
    return saved
