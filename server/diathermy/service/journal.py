"""The write-ahead journal of a session: every command since its checkpoint, replayed on load.

The engine is deterministic bit for bit, so a checkpoint plus the commands taken since (steps and
electrode changes, in their order) rebuild the exact state. A command is appended (one JSON line,
one ``write`` on an ``O_APPEND`` descriptor) after the engine applied it and before anything
acknowledges it (the REST reply, the stream ack or frame), so a process killed at any moment loses
no acknowledged step. Each entry carries a sequence number; the checkpoint records the last one it
contains (``JOURNAL_SEQ_ATTR`` in ``state.h5``), so a crash between writing a checkpoint and
emptying the journal never applies an entry twice.

Lines::

    {"seq": 7, "op": "step", "step": 12, "time_s": 0.36}
    {"seq": 8, "op": "electrode", "name": "active", "update": {"power_w": 30.0}}
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import h5py

from diathermy.errors import CheckpointError

JOURNAL_SEQ_ATTR = "service_journal_seq"
"""Attribute of ``state.h5``: the sequence number of the last journal entry it includes."""

log = logging.getLogger("diathermy.service.journal")


class Journal:
    """One session's ``journal.jsonl``; ``seq`` is the number of the last entry written."""

    def __init__(self, path: Path, *, seq: int = 0, fsync: bool = False) -> None:
        self.path = path
        self.seq = seq
        self.fsync = fsync
        self.torn = False  # the last read found a line cut short (rewrite before appending)

    def append(self, op: str, **data: Any) -> int:
        """Write one entry and return its sequence number (worker thread, under the lock)."""
        self.seq += 1
        line = json.dumps({"seq": self.seq, "op": op, **data}, separators=(",", ":")) + "\n"
        fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.write(fd, line.encode())
            if self.fsync:
                os.fsync(fd)
        finally:
            os.close(fd)
        return self.seq

    def entries(self, *, after: int) -> list[dict[str, Any]]:
        """Entries with ``seq > after`` in order; a torn last line (a write cut short) is dropped."""
        if not self.path.exists():
            return []
        lines = self.path.read_bytes().split(b"\n")
        out = []
        for i, raw in enumerate(lines):
            if not raw.strip():
                continue
            try:
                entry = json.loads(raw)
            except ValueError:
                if i == len(lines) - 1:  # only an unterminated last line can be torn
                    log.warning("dropping a torn journal line", extra={"path": str(self.path)})
                    self.torn = True
                    break
                raise CheckpointError(
                    f"journal {self.path.name}: line {i + 1} is corrupt"
                ) from None
            if int(entry["seq"]) > after:
                out.append(entry)
        return out

    def compact(self, seq: int) -> None:
        """Empty the journal once a checkpoint holding entries up to ``seq`` is in place."""
        kept = self.entries(after=seq)
        tmp = self.path.with_suffix(".tmp")
        tmp.write_text("".join(json.dumps(e, separators=(",", ":")) + "\n" for e in kept))
        os.replace(tmp, self.path)


def checkpoint_seq(path: Path) -> tuple[int, int, float]:
    """(journal seq, step, time in s) recorded in a checkpoint file."""
    try:
        with h5py.File(path, "r") as f:
            return (
                int(f.attrs.get(JOURNAL_SEQ_ATTR, 0)),
                int(f.attrs["step"]),
                float(f.attrs["time_s"]),
            )
    except (OSError, KeyError, ValueError) as err:
        raise CheckpointError(f"checkpoint {path.name} cannot be read: {err}") from None


def mark_checkpoint(path: Path, seq: int) -> None:
    """Record in a freshly written checkpoint that it includes journal entries up to ``seq``."""
    with h5py.File(path, "a") as f:
        f.attrs[JOURNAL_SEQ_ATTR] = seq


def replay(sim: Any, entries: Iterable[dict[str, Any]]) -> int:
    """Apply journal entries to a simulation loaded from the checkpoint; returns the steps taken."""
    steps = 0
    for entry in entries:
        if entry["op"] == "electrode":
            sim.set_electrode(entry["name"], **entry["update"])
        elif entry["op"] == "step":
            sim.step()
            steps += 1
            if int(sim.step_index) != int(entry["step"]):
                raise CheckpointError(
                    f"journal replay reached step {sim.step_index}, the journal says {entry['step']}"
                )
        else:
            raise CheckpointError(f"journal entry {entry['seq']} has an unknown op {entry['op']!r}")
    return steps


def last_step(entries: Iterable[dict[str, Any]]) -> tuple[int, float] | None:
    """(step, time in s) of the last step entry, if any."""
    found = None
    for entry in entries:
        if entry["op"] == "step":
            found = (int(entry["step"]), float(entry["time_s"]))
    return found
