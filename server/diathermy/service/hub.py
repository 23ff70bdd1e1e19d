"""Fan-out of step frames to stream clients: one pending frame per client, newest wins.

After each step the engine process builds and msgpack-encodes each frame once per distinct
subscription (not once per client, ``engine_ops.step_frames``) and ``StreamHub.deliver`` hands
the bytes to the clients, so the event loop only copies bytes to sockets. Each client's sender task takes frames from its ``FrameSlot``: a slow client
never makes the server queue frames, because a new frame replaces the one it has not taken yet,
and the replaced frame is counted as dropped.
"""

from __future__ import annotations

import asyncio
import math
import struct
import threading
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from diathermy.service.encoding import encode_array, pack, sample_nodal

Region = Literal["volume", "top", "surface"]


def finite(obj: Any) -> Any:
    """A copy of a JSON-like value with non-finite floats replaced by None."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite(v) for v in obj]
    if isinstance(obj, np.generic):
        return finite(obj.item())
    return obj


def report_dict(sim: Any) -> dict[str, Any] | None:
    """The last step report of a simulation as a JSON-safe dict."""
    rep = sim.last_report
    return None if rep is None else finite(rep.to_dict())


@dataclass(frozen=True)
class Subscription:
    """What a client wants: which fields, every k-th step, at which precision, where."""

    fields: tuple[str, ...] = ()
    every: int = 1
    dtype: Literal["float16", "float32"] = "float32"
    region: Region = "volume"


def _map_header(n: int) -> bytes:
    """msgpack header of a map with ``n`` entries."""
    return bytes([0x80 | n]) if n < 16 else b"\xde" + struct.pack(">H", n)


@dataclass(frozen=True)
class Frame:
    """One step's message, encoded once: ``n`` msgpack key-value pairs in ``body``.

    The per-client counter ``dropped`` is prepended when the frame is sent (``to_bytes``).
    """

    step: int
    n: int
    body: bytes
    control_id: int = 0  # the electrode controls the frame shows applied
    _last: list[tuple[int, bytes]] = field(default_factory=list, compare=False, repr=False)

    @classmethod
    def encode(cls, message: dict[str, Any]) -> Frame:
        body = b"".join(pack(k) + pack(v) for k, v in message.items())
        control_id = int(message.get("control_id") or 0)
        return cls(step=int(message["step"]), n=len(message), body=body, control_id=control_id)

    def to_bytes(self, dropped: int) -> bytes:
        """The whole msgpack map: the shared pairs plus this client's ``dropped``.

        Clients that keep up share one ``dropped`` count (mostly 0), so the last message built is
        kept and handed to the next client with the same count: one copy of the frame per step,
        not one per client (event-loop thread only)."""
        if self._last and self._last[0][0] == dropped:
            return self._last[0][1]
        data = _map_header(self.n + 1) + pack("dropped") + pack(dropped) + self.body
        self._last[:] = [(dropped, data)]
        return data


class FrameSlot:
    """A one-frame mailbox filled from any thread and emptied by one asyncio task.

    ``wake`` (event-loop thread only) lets the owner wake its sender for other messages too.
    """

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self._lock = threading.Lock()
        self._frame: Frame | None = None
        self._event = asyncio.Event()
        self.dropped = 0

    def put(self, frame: Frame, *, notify: bool = True) -> bool:
        """Store ``frame``; returns True when it replaced an untaken one (a drop).

        ``notify=False`` leaves waking the sender to the caller (``wake_in_turn``)."""
        with self._lock:
            replaced = self._frame is not None
            self._frame = frame
            if replaced:
                self.dropped += 1
        if notify:
            self.loop.call_soon_threadsafe(self._event.set)
        return replaced

    def wake(self) -> None:
        self._event.set()

    async def wait(self) -> Frame | None:
        """Wait for a put or a wake; take the newest frame if there is one."""
        await self._event.wait()
        with self._lock:
            self._event.clear()
            frame, self._frame = self._frame, None
        return frame

    async def get(self) -> Frame:
        """Wait for and take the newest frame."""
        while True:
            frame = await self.wait()
            if frame is not None:
                return frame


@dataclass(eq=False)
class Subscriber:
    """One stream client of a session."""

    slot: FrameSlot
    subscription: Subscription = field(default_factory=Subscription)
    awaiting: int = 0  # id of this client's last electrode control until a frame shows it

    def first_shown_by(self, frame: Frame) -> bool:
        """Whether ``frame`` is the first this client gets that shows its last control."""
        return 0 < self.awaiting <= frame.control_id


def build_payload(sim: Any, sub: Subscription) -> dict[str, Any]:
    """The arrays of a frame: volume fields, their top node layer (the tissue's top face,
    (ny, nx[, 3]): 1 / nz of the bytes), or the cut surface with fields sampled on it."""
    if sub.region == "volume":
        return {"fields": {n: encode_array(sim.field(n), sub.dtype) for n in sub.fields}}
    if sub.region == "top":  # z up: the last node layer is the top face
        return {"fields": {n: encode_array(sim.field(n)[-1], sub.dtype) for n in sub.fields}}
    verts, faces = sim.cut_surface()
    verts = np.asarray(verts, dtype=float).reshape(-1, 3)
    grid = sim.grid
    fields = {
        n: encode_array(
            sample_nodal(
                sim.field(n),
                verts,
                origin_m=grid.origin_m,
                spacing_m=grid.spacing_m if grid.is_uniform else None,
                axes_m=None if grid.is_uniform else grid.axes(),
            ),
            sub.dtype,
        )
        for n in sub.fields
    }
    surface = {
        "vertices": encode_array(verts, sub.dtype),
        "faces": encode_array(np.asarray(faces, dtype=np.int32).reshape(-1, 3)),
    }
    return {"fields": fields, "surface": surface}


class StreamHub:
    """The subscribers of one session."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._subscribers: list[Subscriber] = []

    def add(self, sub: Subscriber) -> None:
        with self._lock:
            self._subscribers.append(sub)

    def remove(self, sub: Subscriber) -> None:
        with self._lock:
            if sub in self._subscribers:
                self._subscribers.remove(sub)

    def __len__(self) -> int:
        with self._lock:
            return len(self._subscribers)

    def subscriptions(self) -> tuple[Subscription, ...]:
        """The distinct subscriptions (the frames a step builds)."""
        with self._lock:
            return tuple(dict.fromkeys(s.subscription for s in self._subscribers))

    def deliver(self, frames: dict[Subscription, Frame]) -> int:
        """Offer each subscriber its subscription's frame of this step; returns the drops.

        The senders are woken (so the frame is written) first for the clients whose last
        electrode control the frame is the first to show: the client steering the electrode
        sees its effect without waiting for the frame's copies to every other client."""
        if not frames:
            return 0
        with self._lock:
            targets = [s for s in self._subscribers if s.subscription in frames]
        targets.sort(key=lambda s: not s.first_shown_by(frames[s.subscription]))
        first = sum(s.first_shown_by(frames[s.subscription]) for s in targets)
        drops = sum(s.slot.put(frames[s.subscription], notify=False) for s in targets)
        if targets:  # one wake-up of the event loop for all of them, not one per client
            slots = [s.slot for s in targets]
            sizes = [len(frames[s.subscription].body) for s in targets]
            targets[0].slot.loop.call_soon_threadsafe(wake_in_turn, slots, sizes, max(1, first))
        return drops


TURN_BYTES = 256 * 1024
"""Frame bytes written per turn of the event loop during a fan-out (at least one frame)."""


def wake_in_turn(slots: list[FrameSlot], sizes: list[int], now: int = 1) -> None:
    """Wake the senders of the first ``now`` slots, then the others a turn of the event loop at a
    time, each turn about ``TURN_BYTES`` of frames (event-loop thread; ``sizes``: the frames'
    bytes, one per slot).

    Each sender writes its frame in the turn after it is woken, and the loop polls the sockets
    between turns: a control message that arrives while a 1.2 MB frame goes out to 16 clients
    is read after one client's write, not after all of them, while 16 small frames (a top face,
    a few kB each) go out in one turn instead of costing 16 polls. The clients the frame first
    shows a control of (``now``) are written together, first."""
    woken, total = now, sum(sizes[:now])
    while woken < len(slots) and total + sizes[woken] <= TURN_BYTES:
        total += sizes[woken]
        woken += 1
    for slot in slots[:woken]:
        slot.wake()
    if len(slots) > woken:
        slots[0].loop.call_soon(wake_in_turn, slots[woken:], sizes[woken:], 1)


def frame_header(sim: Any, *, session_id: str, control_id: int) -> dict[str, Any]:
    """What every frame of this step carries besides its arrays."""
    return {
        "type": "frame",
        "session": session_id,
        "step": int(sim.step_index),
        "time_s": float(sim.time_s),
        "control_id": control_id,
        "report": report_dict(sim),
    }


def current_frame(sim: Any, sub: Subscription, *, session_id: str, control_id: int) -> Frame:
    """The current state as one client's frame (sent after it subscribes)."""
    header = frame_header(sim, session_id=session_id, control_id=control_id)
    return Frame.encode({**header, **build_payload(sim, sub)})
