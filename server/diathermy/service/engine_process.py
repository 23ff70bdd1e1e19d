"""Each loaded session's engine runs in a process of its own, so that stepping never holds the
server's GIL: the event loop writes frames to sockets while the engine steps on another core.

The server holds one ``RemoteSim`` per loaded session: a pipe to its engine process (forked by a
forkserver that has imported the engine once) and what the server reads without asking (step,
time, the last step report, DOF counts), refreshed by every reply. ``call(op, *args)`` runs
``op(sim, *args)`` in the engine process (``op`` is a module-level function, ``engine_ops.py``)
and returns its value or raises its exception; an op that returns ``Replace`` swaps the process's
simulation (create, load, restore). Callers hold the session lock.

Requests can also be pipelined: ``submit`` sends one without waiting and ``receive`` reads the
next reply. The engine process reads every request that has arrived before it runs the next
one and runs the *urgent* ones (electrode controls) first, so a control sent while a step is
queued is applied before that step; each reply carries its request's id, and the replies come in
the order the engine ran the requests, which is the order the server journals them in. A stream
keeps up to two steps in flight this way (``driver.py``), so the engine starts the next step
while the server journals the last one and hands out its frames.

An engine process ends when the server closes the pipe (DELETE, shutdown), when the server dies
(the kernel closes the server's end; mid-step, the parent watch notices that the forkserver,
which leaves with the server, is gone), never on Ctrl-C (the server saves through it first). One
that dies raises ``EngineProcessError``; the session reloads from its checkpoint and journal on
next use.
"""

from __future__ import annotations

import functools
import multiprocessing
import os
import pickle
import signal
import socket
import struct
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.connection import Connection
from multiprocessing.context import BaseContext
from typing import Any

from diathermy.service.cpus import place_engine
from diathermy.service.exceptions import EngineProcessError

PRELOAD = ["diathermy.service.engine_ops"]
"""Imported once by the forkserver, so that a new engine process starts in milliseconds."""


@dataclass(frozen=True)
class Replace:
    """An op's result that makes ``sim`` the engine process's simulation; ``value`` is returned."""

    sim: Any
    value: Any = None


@dataclass(frozen=True)
class SimStatus:
    """What the server reads without a call: step, time s, last step report, DOF counts."""

    step: int
    time_s: float
    report: Any  # engine.report.StepReport | None
    dof_counts: dict[str, int]


@dataclass(frozen=True)
class Reply:
    """The engine's answer to request ``id``: ``value`` is the op's result, or its exception."""

    id: int
    ok: bool
    value: Any


@functools.cache
def _context() -> BaseContext:
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(PRELOAD)
    return ctx


class RemoteSim:
    """The server's handle on one engine process (see the module docstring)."""

    def __init__(self, label: str, cpus: list[int] | None = None) -> None:
        self.label = label
        self.cpus = list(cpus or [])  # the engine process pins itself to these (cpus.py)
        ctx = _context()
        self._conn, child = ctx.Pipe()  # a socket pair
        _widen(self._conn)
        self._reader = ReplyReader(self._conn)
        self._proc = ctx.Process(  # type: ignore[attr-defined]
            target=serve, args=(child, self.cpus), name=f"diathermy-engine-{label}", daemon=True
        )
        self._proc.start()
        child.close()
        self._lock = threading.Lock()  # one caller at a time
        self._send_lock = threading.Lock()  # requests may be sent from any thread
        self._next_id = 0
        self.in_flight = 0  # requests sent whose reply has not been read
        self.failed = False
        self.step_index = 0
        self.time_s = 0.0
        self.last_report: Any = None  # engine.report.StepReport | None
        self.dof_counts: dict[str, int] = {}

    @property
    def pid(self) -> int | None:
        return self._proc.pid

    def call(self, op: Callable[..., Any], *args: Any) -> Any:
        """``op(sim, *args)`` in the engine process; its exceptions are raised here. Nothing
        may be in flight (see ``submit``)."""
        with self._lock:
            rid = self.submit(op, *args)
            reply = self.receive()
        if reply.id != rid:
            raise RuntimeError(f"engine reply {reply.id} answers another request than {rid}")
        if not reply.ok:
            raise reply.value
        return reply.value

    def submit(self, op: Callable[..., Any], *args: Any, urgent: bool = False) -> int:
        """Send ``op(sim, *args)`` without waiting for it; returns the request's id (any thread).

        ``urgent`` requests run before the ones that arrived earlier and wait in the engine
        process (an electrode control before a queued step)."""
        with self._send_lock:
            if self.failed:
                raise self._gone()
            self._next_id += 1
            try:
                self._conn.send((self._next_id, op, args, urgent))
            except OSError:
                self._fail()
                raise self._gone() from None
            self.in_flight += 1
            return self._next_id

    def poll(self, timeout_s: float | None) -> bool:
        """Whether a reply is there to read, waiting up to ``timeout_s`` (None: until one is)."""
        if self.failed:
            raise self._gone()
        try:
            return bool(self._conn.poll(None if timeout_s is None else max(0.0, timeout_s)))
        except (EOFError, OSError):
            self._fail()
            raise self._gone() from None

    def receive(self) -> Reply:
        """The next reply, in the order the engine ran the requests (the thread that holds the
        session lock only: one reader)."""
        if self.failed:
            raise self._gone()
        try:
            rid, ok, value, status = self._reader.recv()
        except (EOFError, OSError):
            self._fail()
            raise self._gone() from None
        with self._send_lock:
            self.in_flight -= 1
        if status is not None:
            self.step_index, self.time_s = status.step, status.time_s
            self.last_report, self.dof_counts = status.report, status.dof_counts
        return Reply(rid, ok, value)

    def _fail(self) -> None:
        self.failed = True
        self.in_flight = 0
        self._reader.close()
        self._proc.join(timeout=2.0)

    def _gone(self) -> EngineProcessError:
        code = self._proc.exitcode
        how = f"signal {-code}" if code is not None and code < 0 else f"exit code {code}"
        return EngineProcessError(
            f"the engine process of session {self.label} ended ({how}); the session is "
            "reloaded from its checkpoint and journal on next use"
        )

    def close(self, timeout_s: float = 10.0) -> None:
        """End the engine process: ask, then wait, then kill (caller holds the session lock)."""
        with self._lock, self._send_lock:
            self.failed = True
            try:
                self._conn.send((0, None, (), False))
            except OSError:
                pass
            self._conn.close()
            self._reader.close()
            self._proc.join(timeout=timeout_s)
            if self._proc.exitcode is None:
                self._proc.kill()
                self._proc.join()


class ReplyReader:
    """Reads the engine's replies off the pipe into one buffer kept across replies.

    ``Connection.recv`` reads a message in chunks, each a fresh bytes object as large as what
    is left to read, gathers them in a ``BytesIO`` and unpickles from there: for a frame of a
    large grid (1.2 MB) that is a few fresh allocations (first-touch page faults) and copies
    per step. This reads the same framing (``multiprocessing.connection``: a 4-byte big-endian
    length, -1 then 8 bytes for larger ones) straight into a reused buffer and unpickles from
    it, which copies each frame once (measured: 0.8 ms instead of 2-4 ms per 1.1 MB reply).
    It reads exactly one message at a time, so ``Connection.poll`` on the same socket stays
    right."""

    KEEP_BYTES = 8 << 20  # a larger message gets a buffer of its own, not kept

    def __init__(self, conn: Connection) -> None:
        self._sock = socket.socket(fileno=os.dup(conn.fileno()))
        self._buf = bytearray(1 << 16)

    def recv(self) -> Any:
        """The next message, unpickled; EOFError when the engine's end is closed."""
        (size,) = struct.unpack("!i", self._read(4, self._buf))
        if size == -1:
            (size,) = struct.unpack("!Q", self._read(8, self._buf))
        buf = self._buf
        if size > len(buf):
            buf = bytearray(size)
            if size <= self.KEEP_BYTES:
                self._buf = buf
        with self._read(size, buf) as data:
            return pickle.loads(data)

    def _read(self, n: int, buf: bytearray) -> memoryview:
        view = memoryview(buf)[:n]
        got = 0
        while got < n:
            k = self._sock.recv_into(view[got:], n - got)
            if k == 0:
                view.release()
                raise EOFError("the engine process closed its pipe")
            got += k
        return view

    def close(self) -> None:
        self._sock.close()


def _widen(conn: Connection, size: int = 4 << 20) -> None:
    """A socket send buffer that takes a whole frame of a large grid (MBs) in one write, so that
    the engine is not woken once per 200 kB while the server reads it (capped by wmem_max)."""
    with socket.socket(fileno=os.dup(conn.fileno())) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, size)


def _watch_parent(parent: int, period_s: float = 0.2) -> None:
    while os.getppid() == parent:
        time.sleep(period_s)
    os._exit(1)  # the forkserver left, so the server did: stop even in the middle of a step


def _status(sim: Any) -> SimStatus | None:
    if sim is None:
        return None
    return SimStatus(
        step=int(sim.step_index),
        time_s=float(sim.time_s),
        report=sim.last_report,
        dof_counts={k: int(v) for k, v in sim.dof_counts().items()},
    )


def serve(conn: Connection, cpus: list[int] | None = None) -> None:
    """The engine process: run ops on its simulation until the pipe closes or says stop; on
    ``cpus`` when given (before it starts any thread, so that they all run there)."""
    from diathermy.runtime import configure_threads

    place_engine(cpus or [])
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the server, which saves via us
    configure_threads()
    _widen(conn)
    threading.Thread(target=_watch_parent, args=(os.getppid(),), daemon=True).start()
    sim: Any = None
    waiting: deque[tuple[int, Any, tuple[Any, ...], bool]] = deque()
    while True:
        try:
            if not waiting:
                waiting.append(conn.recv())
            while conn.poll():  # everything sent so far, so that urgent requests go first
                waiting.append(conn.recv())
        except (EOFError, OSError):
            return
        rid, op, args, _ = _take(waiting)
        if op is None:
            return
        try:
            result = op(sim, *args)
            if isinstance(result, Replace):
                sim, result = result.sim, result.value
            reply: tuple[int, bool, Any, SimStatus | None] = (rid, True, result, _status(sim))
        except Exception as err:
            reply = (rid, False, err, _status(sim))
        try:
            conn.send(reply)
        except OSError:
            return
        except Exception:  # the value or the error could not be pickled
            text = traceback.format_exc(limit=3)
            error = RuntimeError(f"engine reply not sendable: {text}")
            conn.send((rid, False, error, _status(sim)))


def _take(waiting: deque[tuple[int, Any, tuple[Any, ...], bool]]) -> Any:
    """The first urgent request, else the oldest one."""
    for i, request in enumerate(waiting):
        if request[3]:
            del waiting[i]
            return request
    return waiting.popleft()
