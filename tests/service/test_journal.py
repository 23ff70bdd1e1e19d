"""The write-ahead journal: checkpoint + journal replays an uninterrupted run bit for bit, even
when a crash cuts a line short or falls between writing a checkpoint and emptying the journal."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from diathermy.engine.simulation import Simulation
from diathermy.errors import CheckpointError
from diathermy.scene import Scene, builtin_scene
from diathermy.service import engine_ops as ops
from diathermy.service.engine import DefaultEngine
from diathermy.service.engine_process import RemoteSim
from diathermy.service.journal import Journal, mark_checkpoint
from diathermy.service.registry import SessionRecord, SessionRegistry


def small_scene() -> Scene:
    return builtin_scene("default").on_uniform_grid((5, 5, 9))


def run(reg: SessionRegistry, rec: SessionRecord, plan: list[object]) -> None:
    """Steps (ints) and electrode powers (floats), journalled as the service does."""
    assert rec.sim is not None
    for item in plan:
        if isinstance(item, float):
            rec.sim.call(ops.set_electrode, "active", {"power_w": item})
            reg.log_electrode(rec, "active", {"power_w": item})
        else:
            for _ in range(int(item)):  # type: ignore[call-overload]
                rec.sim.call(ops.step_frames, (), rec.id, 0)
                reg.log_step(rec)


def reference(plan: list[object]) -> Simulation:
    sim = Simulation(small_scene())
    for item in plan:
        if isinstance(item, float):
            sim.set_electrode("active", power_w=item)
        else:
            sim.run(int(item))  # type: ignore[call-overload]
    return sim


Registries = Callable[[], SessionRegistry]


@pytest.fixture()
def registry(tmp_path: Path) -> Iterator[Registries]:
    """Fresh registries on one data directory (as after a kill); their engine processes end
    with the test."""
    opened: list[SessionRegistry] = []

    def make() -> SessionRegistry:
        reg = SessionRegistry(tmp_path, DefaultEngine())
        reg.scan()
        opened.append(reg)
        return reg

    yield make
    for reg in opened:
        reg.close_all()


def reload(registry: Registries, sid: str) -> SessionRecord:
    """A fresh registry on the same directory (as after a kill), the session loaded."""
    reg = registry()
    rec = reg.sessions[sid]
    reg.load(rec)
    return rec


def assert_same(a: RemoteSim | None, b: Simulation) -> None:
    assert a is not None and a.step_index == b.step_index
    for name in a.call(ops.field_names):
        np.testing.assert_array_equal(a.call(ops.field, name), b.field(name), err_msg=name)


def test_checkpoint_plus_journal_is_the_uninterrupted_run(registry: Registries) -> None:
    reg = registry()
    rec = reg.create(owner="o", scene=small_scene())
    plan: list[object] = [3, 20.0, 2]
    run(reg, rec, plan)
    reg.save(rec)  # compaction: the journal is emptied into the checkpoint
    assert rec.journal is not None and rec.journal.entries(after=0) == []
    later: list[object] = [2, 80.0, 4]
    run(reg, rec, later)
    got = reload(registry, rec.id)
    assert got.meta["step"] == 11  # listed before loading, from checkpoint + journal
    assert_same(got.sim, reference(plan + later))
    run(reg, got, [1])  # the reloaded session journals on from where it was
    assert_same(reload(registry, rec.id).sim, reference([*plan, *later, 1]))


def test_a_crash_between_checkpoint_and_compaction_applies_nothing_twice(
    registry: Registries,
) -> None:
    reg = registry()
    rec = reg.create(owner="o", scene=small_scene())
    plan: list[object] = [2, 30.0, 3]
    run(reg, rec, plan)
    assert rec.journal is not None
    # the first half of save(): checkpoint written and marked, journal not yet emptied
    tmp = rec.state_path.with_suffix(".h5.tmp")
    assert rec.sim is not None
    rec.sim.call(ops.save_checkpoint, tmp)
    mark_checkpoint(tmp, rec.journal.seq)
    os.replace(tmp, rec.state_path)
    assert len(rec.journal.entries(after=0)) == 6
    assert_same(reload(registry, rec.id).sim, reference(plan))


def test_a_torn_last_line_is_dropped_and_a_corrupt_one_refused(registry: Registries) -> None:
    reg = registry()
    rec = reg.create(owner="o", scene=small_scene())
    run(reg, rec, [3])
    with rec.journal_path.open("ab") as f:
        f.write(b'{"seq": 4, "op": "st')  # the write a kill cut short: never acknowledged
    again = reload(registry, rec.id)
    assert_same(again.sim, reference([3]))
    run(reg, again, [2])  # appended after the torn line was cut away
    assert_same(reload(registry, rec.id).sim, reference([5]))
    text = rec.journal_path.read_bytes().replace(b'"op":"step"', b'"op":"st', 1)
    rec.journal_path.write_bytes(text)
    with pytest.raises(CheckpointError, match="line 1 is corrupt"):
        Journal(rec.journal_path).entries(after=0)
