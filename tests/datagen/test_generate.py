"""Generation end to end with the closed-form physics: determinism, engines, walk rules."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diathermy.datagen import DatagenConfig, DatasetReader, generate, run_scenario
from tests.datagen.fakes import analytic_physics
from tests.datagen.helpers import assert_same_contents


def test_samples_follow_the_walk_rules(tiny_config: DatagenConfig) -> None:
    config = tiny_config.model_copy(update={"n_steps": 25})
    physics = analytic_physics(config)
    nb = physics.mesh.neighbours
    lo, hi, f = config.p_min_pa, config.p_max_pa, config.perturbation
    cases = {"forward": 0, "backtrack": 0, "exhausted": 0}
    for index in range(config.n_scenarios):
        samples = list(run_scenario(config, index, physics))
        assert len(samples) == config.n_steps
        visited = [samples[0].move.tet]
        for prev, s in zip(samples, samples[1:], strict=False):
            healthy = physics.healthy_tets(s.level_set_m)
            if s.move.tet >= 0:
                assert s.move.tet in nb[s.move.parent] and s.move.tet not in visited
                assert healthy[s.move.tet]
                skipped = visited[visited.index(s.move.parent) + 1 :]
                for t in skipped:  # backtracking passed only tets without a way out
                    assert not any(n >= 0 and healthy[n] and n not in visited for n in nb[t])
                cases["backtrack" if skipped else "forward"] += 1
            else:
                for t in visited:  # exhausted: no visited tet has a way out
                    assert not any(n >= 0 and healthy[n] and n not in visited for n in nb[t])
                cases["exhausted"] += 1
            old = prev.p_tet_pa[visited]
            new = s.p_tet_pa[visited]
            assert np.all((new >= lo) & (new <= hi))
            assert np.all((new == lo) | (new == hi) | (np.abs(new / old - 1) <= f * (1 + 1e-12)))
            if s.move.tet >= 0:
                visited.append(s.move.tet)
        untouched = np.setdiff1d(np.arange(physics.mesh.n_tets), visited)
        assert np.all(samples[-1].p_tet_pa[untouched] == config.material.p_atm_pa)
    assert min(cases.values()) >= 1, cases  # the cutting physics exercises every rule


def test_same_seed_gives_bit_identical_files(tmp_path: Path, tiny_config: DatagenConfig) -> None:
    a = generate(tiny_config, tmp_path / "a.h5", factory=analytic_physics)
    generate(tiny_config, tmp_path / "b.h5", factory=analytic_physics)
    assert a.complete_scenarios == 4 and a.samples == 24 and a.computed_scenarios == 4
    assert_same_contents(tmp_path / "a.h5", tmp_path / "b.h5")
    assert not (tmp_path / "a.h5.shards").exists()
    other = tiny_config.model_copy(update={"seed": 8})
    generate(other, tmp_path / "c.h5", factory=analytic_physics)
    with DatasetReader(tmp_path / "a.h5") as ra, DatasetReader(tmp_path / "c.h5") as rc:
        assert not np.array_equal(ra.sample(0)["pressure"], rc.sample(0)["pressure"])


def test_reader_returns_what_the_scenarios_produced(
    tmp_path: Path, tiny_config: DatagenConfig
) -> None:
    generate(tiny_config, tmp_path / "d.h5", factory=analytic_physics)
    physics = analytic_physics(tiny_config)
    with DatasetReader(tmp_path / "d.h5") as r:
        assert len(r) == 24 and r.scenario_ids().tolist() == [0, 1, 2, 3]
        assert r.config["seed"] == 7 and "workers" not in r.config
        for index in (0, 3):
            rows = r.rows_of(index)
            assert r.step_of_row[rows].tolist() == list(range(6))
            for row, s in zip(rows, run_scenario(tiny_config, index, physics), strict=True):
                got = r.sample(int(row))
                assert got["pressure"].shape == (5, 5, 9)
                assert got["displacement"].shape == (5, 5, 9, 3)
                np.testing.assert_array_equal(got["pressure"].ravel(), s.pressure_pa)
                np.testing.assert_array_equal(got["level_set"].ravel(), s.level_set_m)
                np.testing.assert_array_equal(got["displacement"].reshape(-1, 3), s.displacement_m)


def test_two_local_workers_give_the_same_file_as_one(
    tmp_path: Path, tiny_config: DatagenConfig
) -> None:
    generate(tiny_config, tmp_path / "one.h5", factory=analytic_physics, workers=1)
    two = generate(tiny_config, tmp_path / "two.h5", factory=analytic_physics, workers=2)
    assert two.workers == 2
    assert_same_contents(tmp_path / "one.h5", tmp_path / "two.h5")


def test_float32_storage_rounds_once(tmp_path: Path, tiny_config: DatagenConfig) -> None:
    config = tiny_config.model_copy(update={"dtype": "float32", "n_scenarios": 1})
    generate(config, tmp_path / "f.h5", factory=analytic_physics)
    s = next(run_scenario(config, 0, analytic_physics(config)))
    with DatasetReader(tmp_path / "f.h5") as r:
        got = r.sample(0)["pressure"]
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got.ravel(), s.pressure_pa.astype(np.float32))
