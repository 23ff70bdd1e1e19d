"""With the real physics: stored displacement = a fresh FEM solve; the CLI end to end."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from diathermy.cli import main
from diathermy.datagen import DatagenConfig, DatasetReader, generate
from diathermy.datagen.physics import fem_physics
from tests.datagen.helpers import assert_same_contents


@pytest.fixture(scope="module")
def fem_config() -> DatagenConfig:
    """5x5x9 nodes, a tight solver tolerance, and a weak, fast-cutting tissue so the level set
    removes tets within 6 steps (the solves then see ersatz material)."""
    return DatagenConfig(
        grid=(5, 5, 9),
        n_scenarios=2,
        n_steps=6,
        seed=3,
        dtype="float64",
        p_min_pa=4e5,
        p_max_pa=1e6,
        mechanics_rtol=1e-10,
        material={"damage_kappa_j_per_m3": 2e3},
        level_set={"v0_m_per_s": 0.05},
    )


def test_stored_displacement_is_a_fresh_fem_solve_of_stored_inputs(
    tmp_path: Path, fem_config: DatagenConfig
) -> None:
    out = tmp_path / "fem.h5"
    generate(fem_config, out)
    with DatasetReader(out) as r:
        assert len(r) == 12
        for i in range(len(r)):
            s = r.sample(i)
            fresh = fem_physics(fem_config)  # a new solver: no warm start, no reuse
            u, W = fresh.solve(s["pressure"].ravel(), s["level_set"].ravel())
            stored = s["displacement"].reshape(-1, 3)
            assert np.abs(stored).max() > 1e-6  # the pressure really deforms the block
            np.testing.assert_allclose(stored, u, rtol=0, atol=1e-7 * np.abs(u).max())
            assert np.all(W >= 0)
        rows = r.rows_of(0)
        assert r.step_of_row[rows].tolist() == list(range(6))
        phis = np.array([r.sample(int(i))["level_set"] for i in rows])
        assert np.all(np.diff(phis, axis=0) <= 0)  # the cut is irreversible
        physics = fem_physics(fem_config)
        assert (~physics.healthy_tets(phis[-1].ravel())).sum() > 0  # tets were removed
        with h5py.File(out, "r") as f:
            tets, parents = f["walk_tet"][:], f["walk_parent"][:]
        for row in rows[1:]:  # the walk only enters healthy tets
            if tets[row] >= 0:
                assert physics.healthy_tets(phis[row].ravel())[tets[row]]
                assert tets[row] in physics.mesh.neighbours[parents[row]]
        p = r.sample(5)["pressure"]
        assert p.min() >= fem_config.material.p_atm_pa and p.max() <= fem_config.p_max_pa


def test_cli_generates_and_resumes(tmp_path: Path, fem_config: DatagenConfig) -> None:
    cfg = tmp_path / "datagen.json"
    cfg.write_text(fem_config.model_dump_json())
    out = tmp_path / "cli.h5"
    assert main(["datagen", str(cfg), "--out", str(out), "--quiet", "--scenarios", "1"]) == 0
    assert main(["datagen", str(cfg), "--out", str(out), "--quiet", "--resume"]) == 0
    assert (
        main(["datagen", str(cfg), "--out", str(tmp_path / "w2.h5"), "--quiet", "--workers", "2"])
        == 0
    )
    assert_same_contents(out, tmp_path / "w2.h5")
    with DatasetReader(out) as r:
        assert r.scenario_ids().tolist() == [0, 1]
