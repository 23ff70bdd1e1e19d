"""What the service asks of a session's engine process: ``op(sim, *args)`` functions run there
(``engine_process.RemoteSim.call``), each handing back plain values, encoded frames or bytes.

Stepping builds and msgpack-encodes the frames of the step there too, once per distinct
subscription due, so the server only journals the step and writes bytes to sockets.

The engine process counts the electrode controls it applied (``ControlCount``): a stream's controls
may overtake a queued step (``engine_process.py``), so the frame of a step carries the count the
engine had when it took the step. Every request carries the server's count, which the engine
catches up to (a restore bumps it; a new engine process starts from it).
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from diathermy.errors import CheckpointError
from diathermy.scene import Scene
from diathermy.service.engine import EngineAdapter
from diathermy.service.engine_process import Replace
from diathermy.service.exceptions import BadRequestError, NotFoundError
from diathermy.service.hub import Frame, Subscription, build_payload, current_frame, frame_header


def create(_sim: Any, engine: EngineAdapter, scene: Scene) -> Replace:
    """A new simulation of ``scene``."""
    return Replace(engine.create(scene))


def load(_sim: Any, engine: EngineAdapter, path: Path) -> Replace:
    """The simulation of a checkpoint file."""
    return Replace(engine.load(path))


def restore(sim: Any, engine: EngineAdapter, path: Path, snapshot_id: str) -> Replace:
    """The simulation of a snapshot, which must be on the session's grid."""
    new = engine.load(path)
    if tuple(new.grid.shape) != tuple(sim.grid.shape):
        raise CheckpointError(f"snapshot {snapshot_id!r} does not match the session's grid")
    return Replace(new)


def sim_meta(sim: Any) -> dict[str, Any]:
    """What a listing needs without loading the simulation."""
    g = sim.grid
    return {
        "scene_name": sim.scene.name,
        "grid": {
            "shape": list(g.shape),
            "spacing_m": list(g.spacing_m) if g.is_uniform else None,
            "axes_m": None if g.is_uniform else [a.tolist() for a in g.axes()],
            "origin_m": list(g.origin_m),
            "size_m": list(g.size_m),
            "n_nodes": int(g.n_nodes),
        },
        "effects": list(sim.effects),
        "dof_counts": {k: int(v) for k, v in sim.dof_counts().items()},
        "step": int(sim.step_index),
        "time_s": float(sim.time_s),
    }


def save_checkpoint(sim: Any, path: Path) -> None:
    sim.save_checkpoint(path)


class ControlCount:
    """The id of the last electrode control applied in this engine process (one per session)."""

    last = 0

    @classmethod
    def catch_up(cls, server_count: int) -> int:
        cls.last = max(cls.last, int(server_count))
        return cls.last


def step_frames(
    sim: Any, subscriptions: tuple[Subscription, ...], session_id: str, control_id: int
) -> tuple[Any, dict[Subscription, Frame]]:
    """Take one step; (its report, the frame of each subscription due at the new step).

    ``control_id``: the server's control count when it asked (frames carry the engine's)."""
    control_id = ControlCount.catch_up(control_id)
    report = sim.step()
    due = [s for s in subscriptions if sim.step_index % s.every == 0]
    if not due:
        return report, {}
    header = frame_header(sim, session_id=session_id, control_id=control_id)
    return report, {s: Frame.encode({**header, **build_payload(sim, s)}) for s in due}


def set_electrode(sim: Any, name: str, changes: dict[str, Any]) -> int:
    """Apply electrode changes from the next step; returns the step they apply after."""
    names = [e.name for e in sim.scene.electrodes]
    if name not in names:
        raise NotFoundError(
            f"unknown electrode {name!r}; electrodes: {', '.join(names)}", field="name"
        )
    sim.set_electrode(name, **changes)
    return int(sim.step_index)


def apply_control(sim: Any, name: str, changes: dict[str, Any], control_id: int) -> tuple[int, int]:
    """Apply electrode changes from the next step; (the control's id, the step it applies
    after). ``control_id``: the server's control count when it asked."""
    step = set_electrode(sim, name, changes)
    ControlCount.last = ControlCount.catch_up(control_id) + 1
    return ControlCount.last, step


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


def read_fields(
    sim: Any, fields: str | None, dtype: str
) -> tuple[int, float, dict[str, np.ndarray]]:
    """(step, time s, arrays) of the named fields, floats cast to ``dtype``."""
    names = parse_field_names(fields, list(sim.field_names()))
    arrays = {n: np.asarray(sim.field(n)) for n in names}
    with np.errstate(over="ignore"):
        arrays = {n: a.astype(dtype) if a.dtype.kind == "f" else a for n, a in arrays.items()}
    return int(sim.step_index), float(sim.time_s), arrays


def read_surface(sim: Any) -> tuple[int, float, np.ndarray, np.ndarray]:
    """(step, time s, vertices (n, 3) m, faces (m, 3)) of the cut surface."""
    verts, faces = sim.cut_surface()
    return (
        int(sim.step_index),
        float(sim.time_s),
        np.asarray(verts, dtype=float).reshape(-1, 3),
        np.asarray(faces, dtype=np.int64).reshape(-1, 3),
    )


def vtu_bytes(sim: Any) -> bytes:
    """The current state as a ParaView .vtu file."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "state.vtu"
        sim.write_vtu(path)
        return path.read_bytes()


def hello(sim: Any, session_id: str) -> dict[str, Any]:
    """A stream's first message."""
    return {
        "type": "hello",
        "session": session_id,
        "step": int(sim.step_index),
        "time_s": float(sim.time_s),
        "fields": list(sim.field_names()),
        "effects": list(sim.effects),
        "electrodes": [e.name for e in sim.scene.electrodes],
    }


def subscribe_frame(sim: Any, sub: Subscription, session_id: str, control_id: int) -> Frame:
    """Check a subscription against the session; the current state as its frame."""
    available = list(sim.field_names())
    for i, name in enumerate(sub.fields):
        if name not in available:
            raise BadRequestError(
                f"unknown field {name!r}; available: {', '.join(available)}", field=f"fields.{i}"
            )
        if sub.region != "volume" and sim.field(name).ndim == 1:
            raise BadRequestError(
                f"{name!r} is per-element; the {sub.region} region carries nodal fields only",
                field=f"fields.{i}",
            )
    return current_frame(sim, sub, session_id=session_id, control_id=control_id)


def field_names(sim: Any) -> list[str]:
    return list(sim.field_names())


def field(sim: Any, name: str) -> np.ndarray:
    return np.asarray(sim.field(name))
