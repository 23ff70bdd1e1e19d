"""The change set of a step is exact: it names every node and tet whose value changed (and
nothing else), the tets the cut removed, and whether the electrode contact moved."""

from __future__ import annotations

import numpy as np

from diathermy.engine.changes import changed_entries
from diathermy.engine.simulation import Simulation
from diathermy.scene.models import Electrode, ElectrodePath
from tests.engine.scenes import tiny_scene


def _check_exact(sim: Simulation, before: dict[str, np.ndarray]) -> None:
    ch = sim.last_changes
    assert ch is not None
    for name, new in sim.state.arrays.items():
        expected = changed_entries(before[name], new)
        got = ch.changed_tets(name) if name in ch.tets else ch.changed_nodes(name)
        assert np.array_equal(got, expected), name
    was, now = before["removed"], sim.state["removed"]
    assert np.array_equal(ch.removed_tets, np.flatnonzero(now & ~was))
    union = None
    for per_effect in sim.last_effect_changes.values():
        union = per_effect if union is None else union.merge(per_effect)
    assert union is not None
    for name, idx in {**ch.nodes, **ch.tets}.items():  # every change is some effect's
        assert np.isin(idx, {**union.nodes, **union.tets}[name]).all(), name


def test_a_step_that_changes_nothing_reports_no_change():
    """No power and a block at ambient temperature: every effect is skipped and nothing moves."""
    scene = tiny_scene(
        electrodes=[Electrode(position_m=(0.01, 0.005), power_w=0.0)],
        material={"t_initial_k": 293.15, "t_ambient_k": 293.15},
    )
    sim = Simulation(scene)
    for _ in range(3):
        rep = sim.step()
        assert not any(e.ran for e in rep.effects.values())
        assert sim.last_changes is not None and sim.last_changes.empty
        assert all(c.empty for c in sim.last_effect_changes.values())


def test_changes_are_exact_through_boiling_and_the_cut():
    sim = Simulation(tiny_scene())
    cut_steps = 0
    for _ in range(30):
        before = {k: v.copy() for k, v in sim.state.arrays.items()}
        sim.step()
        _check_exact(sim, before)
        cut_steps += sim.last_changes.removed_tets.size > 0
        assert not sim.last_changes.contact_moved or sim.step_index == 1 or cut_steps
    assert cut_steps > 0
    ch = sim.last_effect_changes
    assert set(ch["thermal"].nodes) <= {"temperature"}  # an effect changes only what it writes
    assert set(ch["mechanics"].nodes) <= {"displacement"}


def test_a_moving_electrode_moves_the_contact():
    path = ElectrodePath(waypoints_m=[(0.005, 0.005), (0.015, 0.005)], speed_m_per_s=0.002)
    sim = Simulation(
        tiny_scene(electrodes=[Electrode(position_m=(0.005, 0.005), path=path, power_w=5.0)])
    )
    moved = []
    for _ in range(5):
        before = {k: v.copy() for k, v in sim.state.arrays.items()}
        sim.step()
        _check_exact(sim, before)
        moved.append(sim.last_changes.contact_moved)
    assert all(moved)
    fixed = Simulation(tiny_scene(electrodes=[Electrode(position_m=(0.01, 0.005), power_w=5.0)]))
    fixed.run(2)
    assert fixed.last_changes is not None and not fixed.last_changes.contact_moved
