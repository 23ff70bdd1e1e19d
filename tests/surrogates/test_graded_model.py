"""A network for a graded grid (issue #22, item 4): its checkpoint carries the grid's node
coordinates, it loads only on that grid, and 'auto' asks it on the engine's graded grids."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from diathermy.engine.simulation import Simulation
from diathermy.errors import CheckpointError
from diathermy.mesh import Grid, build_tet_mesh
from diathermy.physics.incremental_mechanics import IncrementalFEMBackend
from diathermy.physics.strain_energy import relative_strain_energy_error
from diathermy.scene import Resolution, SolverConfig
from diathermy.surrogates.checkpoint import grid_mismatch, load_checkpoint, save_checkpoint
from diathermy.surrogates.cnn import CNNConfig, DisplacementCNN
from diathermy.surrogates.predictor import CNNPredictor
from tests.engine.scenes import tiny_scene

RES = Resolution(fine_m=1.5e-3, margin_m=1e-3, depth_m=3e-3)


def _graded_grid() -> Grid:
    return tiny_scene(resolution=RES).node_grid()


def _model_for(grid: Grid, path: Path, shift_m: float = 0.0) -> Path:
    torch.manual_seed(0)
    model = DisplacementCNN(CNNConfig(width=4, depth=2))
    x, y, z = grid.axes()
    save_checkpoint(path, model, grid_shape=grid.shape, spacing_m=grid.min_spacing_m,
                    axes_m=(x + shift_m, y, z))  # fmt: skip
    return path


def test_a_graded_model_loads_on_its_own_grid_only(tmp_path: Path) -> None:
    grid = _graded_grid()
    assert not grid.is_uniform
    mesh = build_tet_mesh(grid)
    net = CNNPredictor(mesh, _model_for(grid, tmp_path / "own.pt"), device="cpu")
    u = net.predict(np.full(mesh.n_nodes, 2e5), np.full(mesh.n_nodes, 1e-3))
    assert u.shape == (mesh.n_nodes, 3) and np.isfinite(u).all()
    ckpt = load_checkpoint(tmp_path / "own.pt", expected_grid=grid.shape)
    assert ckpt.axes_m is not None and grid_mismatch(ckpt, grid, "own.pt") is None
    # the same node counts with x nodes 0.1 mm off: another grid
    with pytest.raises(CheckpointError, match="other x node coordinates"):
        CNNPredictor(mesh, _model_for(grid, tmp_path / "shifted.pt", 1e-4), device="cpu")
    # a graded model on the uniform grid of the same node counts, and a uniform one on the graded
    uniform = Grid(grid.shape, size_m=grid.size_m)
    with pytest.raises(CheckpointError, match="other . node coordinates"):
        CNNPredictor(build_tet_mesh(uniform), tmp_path / "own.pt", device="cpu")
    plain = tmp_path / "uniform.pt"
    save_checkpoint(plain, DisplacementCNN(CNNConfig(width=4, depth=2)), grid_shape=grid.shape,
                    spacing_m=uniform.spacing_m)  # fmt: skip
    with pytest.raises(CheckpointError, match="trained for a uniform grid"):
        CNNPredictor(mesh, plain, device="cpu")


def test_axes_that_do_not_fit_the_grid_are_refused(tmp_path: Path) -> None:
    grid = _graded_grid()
    x, y, z = grid.axes()
    model = DisplacementCNN(CNNConfig(width=4, depth=2))
    with pytest.raises(CheckpointError, match="axes_m has"):
        save_checkpoint(tmp_path / "m.pt", model, grid_shape=grid.shape,
                        spacing_m=grid.min_spacing_m, axes_m=(x[:-1], y, z))  # fmt: skip
    path = _model_for(grid, tmp_path / "m.pt")
    payload = torch.load(path, weights_only=True)
    payload["axes_m"] = [[0.0, 1.0]] * 3
    torch.save(payload, tmp_path / "bad.pt")
    with pytest.raises(CheckpointError, match="axes_m does not fit"):
        load_checkpoint(tmp_path / "bad.pt")


def test_auto_asks_the_graded_grids_network_first(tmp_path: Path) -> None:
    """On a graded grid with a model for it, 'auto' takes the network on the first mechanics
    step and persistence after, and the run stays within the issue's tolerances of full solves;
    with a model for another grid it runs on persistence and says why."""
    grid = _graded_grid()
    model = _model_for(grid, tmp_path / "net.pt")
    auto = Simulation(tiny_scene(resolution=RES, mechanics={"predictor": "auto",
                                                             "model": str(model)}))  # fmt: skip
    full = Simulation(tiny_scene(resolution=RES, solver=SolverConfig(incremental=False)))
    backend = auto.ctx.mechanics
    assert isinstance(backend, IncrementalFEMBackend) and backend.network is not None
    picks = []
    for _ in range(30):
        mech = auto.step().effects["mechanics"]
        full.step()
        if mech.ran:
            picks.append(mech.extra["predictor"])
            W, W_ref = auto.state["strain_energy"], full.state["strain_energy"]
            assert relative_strain_energy_error(W, W_ref) <= 0.01
        if len(picks) == 4:
            break
    assert picks[0] == "cnn" and set(picks[1:]) <= {"previous"}, picks
    other = _model_for(grid, tmp_path / "other.pt", 1e-4)
    sim = Simulation(tiny_scene(resolution=RES, mechanics={"predictor": "auto",
                                                            "model": str(other)}))  # fmt: skip
    backend = sim.ctx.mechanics
    assert isinstance(backend, IncrementalFEMBackend) and backend.network is None
    assert "other x node coordinates" in (backend.network_unavailable or "")
