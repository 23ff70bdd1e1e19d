"""The hybrid-CNN backend: agreement with FEM, the guard, model errors, the engine end to end."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from diathermy.cli import main
from diathermy.engine.simulation import Simulation
from diathermy.errors import CheckpointError, SceneError
from diathermy.fem.geometry import structured_geometry
from diathermy.physics.strain_energy import relative_strain_energy_error, strain_energy_density
from diathermy.surrogates.backend import CNNBackend, default_model_path
from diathermy.surrogates.checkpoint import load_checkpoint
from tests.engine.scenes import tiny_scene
from tests.surrogates.hybrid_helpers import (
    GRID,
    FemSample,
    fem_sample,
    overfit_model,
    untrained_model,
)

NU = 0.4
P0 = 101325.0


@pytest.fixture(scope="module")
def sample() -> FemSample:
    return fem_sample()


@pytest.fixture(scope="module")
def fitted(sample: FemSample, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return overfit_model(sample, tmp_path_factory.mktemp("hybrid") / "fitted.pt")


def _backend(
    path: Path, sample: FemSample, tol: float | None, pre: str = "jacobi", correction: str = "none"
) -> CNNBackend:
    return CNNBackend(
        sample.mesh,
        path,
        poisson_ratio=NU,
        p0_pa=P0,
        ersatz_ratio=1e-6,
        guard_tolerance=tol,
        guard_preconditioner=pre,  # type: ignore[arg-type]
        correction=correction,  # type: ignore[arg-type]
    )


def _step(backend: CNNBackend, s: FemSample):  # noqa: ANN202
    return backend.solve(
        pressure_pa=s.pressure_pa,
        level_set_m=s.level_set_m,
        youngs_modulus_pa=s.youngs_modulus_pa,
        healthy=s.healthy,
        warm_start=None,
    )


def _se_error(s: FemSample, u: np.ndarray) -> float:
    geom = structured_geometry(s.mesh.points, s.mesh.tets, s.mesh.shape_id)
    W = strain_energy_density(geom.grads, s.mesh.tets, u, s.youngs_modulus_pa, NU)
    W_ref = strain_energy_density(geom.grads, s.mesh.tets, s.u, s.youngs_modulus_pa, NU)
    return relative_strain_energy_error(W, W_ref)


def test_step_agrees_with_fem_on_its_training_sample(
    sample: FemSample, fitted: Path, tmp_path: Path
) -> None:
    out = _step(_backend(fitted, sample, None), sample)
    rel_u = np.linalg.norm(out.u - sample.u) / np.linalg.norm(sample.u)
    untrained = _step(_backend(untrained_model(tmp_path / "u.pt"), sample, None), sample)
    # a width-8 net fit in 100 L-BFGS iterations: close, not exact (the guard makes it exact)
    assert rel_u < 0.25
    assert _se_error(sample, out.u) < 0.5 < _se_error(sample, untrained.u)
    assert out.extra["corrected"] is False and out.iterations == 0
    assert out.residual == out.extra["residual_before"] > 0
    assert np.all(out.u[sample.mesh.side_nodes("z-")] == 0.0)  # the clamped bottom is held


def test_guard_brings_the_residual_under_tolerance_and_the_energy_error_down(
    sample: FemSample, fitted: Path
) -> None:
    plain = _step(_backend(fitted, sample, None), sample)
    backend = _backend(fitted, sample, 1e-3)
    out = _step(backend, sample)
    assert out.extra["residual_before"] == pytest.approx(plain.residual) and plain.residual > 1e-3
    assert out.extra["corrected"] is True and out.extra["residual_after"] <= 1e-3
    assert out.residual == out.extra["residual_after"]
    assert 0 < out.iterations == out.extra["guard_iterations"] < 200
    assert _se_error(sample, out.u) < 1e-2 < _se_error(sample, plain.u)
    amg = _backend(fitted, sample, 1e-3, "amg")
    via_amg = _step(amg, sample)  # the AMG variant builds the FEM solver once per topology
    assert via_amg.extra["residual_after"] <= 1e-3 and amg.n_builds == 1
    assert _step(amg, sample).rebuilt is False and amg.n_builds == 1
    again = _step(backend, sample)  # Jacobi-CG on the kept stiffness: no solver is ever built
    assert again.rebuilt is False and backend.n_builds == 0 and backend.n_corrections == 2


def test_patch_correction_cuts_the_energy_error_where_the_residual_is(
    sample: FemSample, fitted: Path, tmp_path: Path
) -> None:
    for path in (fitted, untrained_model(tmp_path / "u.pt")):
        plain = _step(_backend(path, sample, None), sample)
        patched = _step(_backend(path, sample, None, correction="patch"), sample)
        assert plain.extra["patch_nodes"] == 0 and plain.extra["correction"] == "none"
        assert 0 < patched.extra["patch_nodes"] < sample.mesh.n_nodes
        assert patched.extra["residual_before"] == pytest.approx(plain.residual)
        assert patched.residual == patched.extra["residual_after"] < plain.residual
        assert _se_error(sample, patched.u) < 0.5 * _se_error(sample, plain.u)
        assert np.all(patched.u[sample.mesh.side_nodes("z-")] == 0.0)
    # the guard finishes from the patched u
    guarded = _step(_backend(fitted, sample, 1e-3, correction="patch"), sample)
    assert guarded.extra["corrected"] is True and guarded.extra["residual_after"] <= 1e-3


@pytest.mark.parametrize(
    ("kw", "field"),
    [
        ({"correction": "global"}, "mechanics.correction"),
        ({"patch_threshold": 0.0}, "mechanics.patch_threshold"),
        ({"patch_threshold": 2.0}, "mechanics.patch_threshold"),
        ({"patch_layers": -1}, "mechanics.patch_layers"),
        ({"patch_max_nodes": 0}, "patch_max_nodes"),
    ],
)
def test_bad_patch_settings_are_refused(
    sample: FemSample, fitted: Path, kw: dict[str, object], field: str
) -> None:
    with pytest.raises(SceneError, match=field):
        CNNBackend(sample.mesh, fitted, poisson_ratio=NU, p0_pa=P0, ersatz_ratio=1e-6, **kw)  # type: ignore[arg-type]


def test_model_for_another_grid_or_corrupt_file_is_refused(
    sample: FemSample, tmp_path: Path
) -> None:
    other = untrained_model(tmp_path / "other.pt", grid=(5, 5, 9))
    with pytest.raises(CheckpointError, match=r"trained for grid 5x5x9 .* the scene uses 9x9x17"):
        _backend(other, sample, None)
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint at all")
    with pytest.raises(CheckpointError, match="not a readable diathermy CNN checkpoint"):
        _backend(bad, sample, None)
    with pytest.raises(CheckpointError, match="does not exist"):
        _backend(tmp_path / "missing.pt", sample, None)


def test_model_for_another_block_size_is_refused(tmp_path: Path) -> None:
    from diathermy.mesh import Grid, build_tet_mesh

    model = untrained_model(tmp_path / "m.pt")  # 9x9x17 on the 2 x 1 x 1 cm block
    mesh = build_tet_mesh(Grid(GRID, size_m=(0.2, 0.1, 0.1)))
    with pytest.raises(CheckpointError, match="node spacing"):
        CNNBackend(mesh, model, poisson_ratio=NU, p0_pa=P0, ersatz_ratio=1e-6)


def test_no_shipped_model_for_a_grid_names_the_shipped_ones() -> None:
    with pytest.raises(
        SceneError, match=r"no shipped CNN for grid 9x9x17 \(shipped grids: 33x33x65\)"
    ):
        default_model_path(GRID)


def test_cli_reports_a_bad_model_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = tmp_path / "tiny.json"
    scene.write_text(tiny_scene().model_dump_json())
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"\x00" * 64)
    argv = ["simulate", str(scene), "--mechanics", "cnn", "--model", str(bad)]
    code = main([*argv, "--out", str(tmp_path / "run.h5"), "--steps", "2", "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and "bad.pt" in err and "checkpoint" in err


def test_engine_with_cnn_runs_end_to_end_and_tracks_fem(fitted: Path) -> None:
    steps = 9  # boils by step ~5; no cut yet, so both runs see the same p and phi
    fem = Simulation(tiny_scene(steps=steps))
    hybrid = Simulation(
        tiny_scene(
            steps=steps, mechanics={"backend": "cnn", "model": str(fitted), "guard_tolerance": 1e-3}
        )
    )
    assert hybrid.mechanics.name == "cnn"
    fem.run(steps)
    reports = hybrid.run(steps)
    mech = [r.effects["mechanics"] for r in reports if r.ran("mechanics")]
    assert len(mech) >= 2
    assert all(m.extra["backend"] == "cnn" and m.extra["residual_after"] <= 1e-3 for m in mech)
    W, W_ref = hybrid.state["strain_energy"], fem.state["strain_energy"]
    assert np.all(np.isfinite(W)) and W_ref.max() > 0
    assert relative_strain_energy_error(W, W_ref) < 1e-2


def test_shipped_default_model_loads_for_the_default_grid() -> None:
    from diathermy.scene import Scene

    grid = Scene().grid
    path = default_model_path(grid)
    ckpt = load_checkpoint(path, expected_grid=grid)
    assert ckpt.grid_shape == (33, 33, 65) and ckpt.model.config.width <= 16
    assert path.stat().st_size < 1_000_000
    metrics = json.loads(path.with_suffix(".json").read_text())
    assert 0 <= metrics["validation"]["mean_strain_energy_error"] < 1.0


def test_engine_patch_correction_is_the_default_and_the_scene_can_turn_it_off(
    fitted: Path,
) -> None:
    steps = 9
    fem = Simulation(tiny_scene(steps=steps))
    fem.run(steps)
    errors, modes = {}, {}
    for correction in ("patch", "none"):
        mech_cfg: dict[str, object] = {"backend": "cnn", "model": str(fitted)}
        if correction == "none":
            mech_cfg["correction"] = "none"
        sim = Simulation(tiny_scene(steps=steps, mechanics=mech_cfg))
        reports = sim.run(steps)
        mech = [r.effects["mechanics"] for r in reports if r.ran("mechanics")]
        assert len(mech) >= 2
        modes[correction] = {m.extra["correction"] for m in mech}
        nodes = [m.extra["patch_nodes"] for m in mech]
        assert all(n > 0 for n in nodes) if correction == "patch" else nodes == [0] * len(nodes)
        errors[correction] = relative_strain_energy_error(
            sim.state["strain_energy"], fem.state["strain_energy"]
        )
    assert modes == {"patch": {"patch"}, "none": {"none"}}
    assert errors["patch"] < 0.5 * errors["none"]


def test_cli_correction_flag_reaches_the_run_file(fitted: Path, tmp_path: Path) -> None:
    import h5py

    scene = tmp_path / "tiny.json"
    scene.write_text(tiny_scene().model_dump_json())
    out = tmp_path / "run.h5"
    argv = ["simulate", str(scene), "--mechanics", "cnn", "--model", str(fitted)]
    assert main([*argv, "--correction", "none", "--out", str(out), "--steps", "9", "--quiet"]) == 0
    with h5py.File(out, "r") as f:
        reports = [json.loads(r) for r in f["reports"][...]]
    mech = [r["effects"]["mechanics"] for r in reports if r["effects"]["mechanics"]["ran"]]
    assert mech and all(m["extra"]["correction"] == "none" for m in mech)
