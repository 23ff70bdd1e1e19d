"""Engine samples: random held-out-safe scenes, recorded FEM steps, merged dataset files."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from diathermy.datagen.engine_samples import (
    EngineSamplesConfig,
    merge_datasets,
    random_scene,
    write_engine_samples,
)
from diathermy.scene import builtin_scene
from diathermy.surrogates.data import read_dataset_info, read_samples

TINY = EngineSamplesConfig(
    grid=(7, 7, 13), block_m=(0.02, 0.01, 0.01), n_runs=2, n_steps=9, record_every=2,
    power_w=(30.0, 40.0), margin_m=0.004, seed=3,
)  # fmt: skip


def test_random_scenes_are_reproducible_and_never_the_built_in_ones() -> None:
    a, b = random_scene(TINY, 0), random_scene(TINY, 0)
    assert a == b and random_scene(TINY, 1) != a
    held_out = [builtin_scene(n).electrodes[0] for n in ("fixed-electrode", "moving-electrode")]
    for i in range(20):
        el = random_scene(EngineSamplesConfig(seed=i), i).electrodes[0]
        assert all(el != h for h in held_out)
        assert 30.0 <= el.power_w <= 70.0


def test_recorded_samples_are_fem_solutions_and_merge_renumbers_scenarios(tmp_path: Path) -> None:
    from diathermy.mesh import Grid, build_tet_mesh
    from diathermy.physics.mechanics import MechanicsSolver
    from diathermy.physics.topology import removed_fraction, removed_tets

    n = write_engine_samples(TINY, tmp_path / "e.h5", log=False)
    assert n > 0
    info = read_dataset_info(tmp_path / "e.h5")
    assert info.grid_shape == TINY.grid and info.n_samples == n
    # a recorded u solves the FEM system of its own (p, phi): re-solve and compare
    p, phi, u = read_samples(str(tmp_path / "e.h5"), np.array([n - 1]))
    mesh = build_tet_mesh(Grid(TINY.grid, size_m=TINY.block_m))
    removed = removed_tets(removed_fraction(phi[0].ravel().astype(float), mesh.tets))
    E = np.where(removed, 1e-6, 1.0) * 2.7e5
    ref = (
        MechanicsSolver(mesh, E, 0.4, healthy=~removed, rtol=1e-10).solve(p[0].ravel(), 101325.0).u
    )
    np.testing.assert_allclose(u[0].reshape(-1, 3), ref, atol=1e-4 * np.abs(ref).max())
    total = merge_datasets([tmp_path / "e.h5", tmp_path / "e.h5"], tmp_path / "m.h5")
    assert total == 2 * n
    merged = read_dataset_info(tmp_path / "m.h5")
    assert len(merged.complete_scenarios()) == 2 * len(info.complete_scenarios())
    with h5py.File(tmp_path / "m.h5") as f, h5py.File(tmp_path / "e.h5") as g:
        np.testing.assert_array_equal(f["displacement"][n:], g["displacement"][:])


def test_scene_samples_record_the_given_scenes_as_their_own_scenarios(tmp_path: Path) -> None:
    import pytest

    from diathermy.datagen.engine_samples import write_scene_samples

    scenes = [random_scene(TINY, 0), random_scene(TINY, 1)]
    n = write_scene_samples(
        scenes, tmp_path / "s.h5", n_steps=TINY.n_steps, record_every=2, log=False
    )
    m = write_engine_samples(TINY, tmp_path / "e.h5", log=False)
    assert n == m > 0  # the same runs, recorded alike
    with h5py.File(tmp_path / "s.h5") as f, h5py.File(tmp_path / "e.h5") as g:
        np.testing.assert_array_equal(f["scenario"][:], g["scenario"][:])
        np.testing.assert_array_equal(f["displacement"][:], g["displacement"][:])
    with pytest.raises(ValueError, match="one grid"):
        write_scene_samples(
            [scenes[0], builtin_scene("fixed-electrode").on_uniform_grid((33, 33, 65))],
            tmp_path / "x.h5",
            n_steps=1,
            log=False,
        )


def test_cli_bad_input_is_one_line(tmp_path: Path) -> None:
    import subprocess
    import sys

    for args in (
        ["--scene", "no-such-scene"],
        ["--scene", "default", "--grid", "1", "1", "1"],
        ["--merge", str(tmp_path / "missing.h5")],
    ):
        proc = subprocess.run(
            [sys.executable, "-m", "diathermy.datagen.engine_samples", *args, "--steps", "2",
             "--out", str(tmp_path / "o.h5")],
            capture_output=True, text=True,
        )  # fmt: skip
        assert proc.returncode == 2, proc.stderr
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and "error:" in lines[0] and "Traceback" not in proc.stderr
