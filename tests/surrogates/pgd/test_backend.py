"""The PGD backend in the engine, online enrichment, and the pgd-build CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from diathermy.cli import main
from diathermy.engine.simulation import Simulation
from diathermy.errors import CheckpointError, SceneError
from diathermy.scene import Scene
from diathermy.surrogates.pgd.model import PGDModel, load_model
from tests.surrogates.pgd.conftest import GRID


def _hot_sim(model_file: Path | None, **mech) -> Simulation:
    """Thermal + EOS + mechanics on 9x9x17, with a boiling spot under the electrode."""
    scene = Scene(
        grid=GRID,
        effects=["mechanics"],
        mechanics={"backend": "pgd", "model": str(model_file) if model_file else None, **mech},
        steps=3,
    )
    sim = Simulation(scene)
    pts = sim.disc.mesh.points
    hot = np.linalg.norm(pts - np.array([0.1, 0.05, 0.1]), axis=1) < 0.02
    sim.state["temperature"] = np.where(hot, 420.0, sim.state["temperature"])
    return sim


def test_backend_runs_in_the_engine(tiny_model_file: Path) -> None:
    sim = _hot_sim(tiny_model_file)
    reports = sim.run(3)
    mech = [r.effects["mechanics"] for r in reports]
    assert all(m.ran and m.extra["backend"] == "pgd" for m in mech)
    u = sim.state["displacement"]
    assert np.all(np.isfinite(u)) and np.all(np.isfinite(sim.state["strain_energy"]))
    top = np.argmin(np.linalg.norm(sim.disc.mesh.points - [0.1, 0.05, 0.1], axis=1))
    assert u[top, 2] > 0  # the pressurised spot swells: the surface above it rises
    assert mech[-1].extra["strength_pa_m3"] > 0 and not mech[-1].extra["residual_checked"]


def test_online_enrichment_reaches_the_fem_answer(tiny_model_file: Path) -> None:
    sim = _hot_sim(tiny_model_file, guard_tolerance=1e-3)
    rep = sim.step()
    m = rep.effects["mechanics"]
    assert m.extra["residual_checked"] and m.extra["enriched"] and m.extra["indicator"] > 1e-3
    assert m.extra["online_modes"] == 1 and m.extra["enrich_s"] > 0
    assert rep.effects["mechanics"].extra["residual"] < 1e-3
    backend = sim.mechanics
    assert backend.model.n_online == 1  # type: ignore[attr-defined]


def test_missing_or_foreign_model_is_a_clear_error(tmp_path: Path, tiny_model_file: Path) -> None:
    with pytest.raises(SceneError, match="needs mechanics.model"):
        _hot_sim(None)  # the backend is built with the simulation: a missing model fails at once
    scene = Scene(
        grid=(9, 9, 9),
        effects=["mechanics"],
        mechanics={"backend": "pgd", "model": str(tiny_model_file)},
    )
    with pytest.raises(CheckpointError, match="built for grid 9x9x17"):
        _ = Simulation(scene).mechanics


def test_pgd_build_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = {
        "scene": "default",
        "grid": list(GRID),
        "manifold": {
            "electrode_x_m": [0.1],
            "electrode_y_m": [0.05],
            "radius_m": [0.01],
            "craters": [[0.1, 0.05, 0.0], [0.1, 0.05, 0.02]],
            "fem_rtol": 1e-6,
        },
    }
    path = tmp_path / "pgd.json"
    path.write_text(json.dumps(cfg))
    out = tmp_path / "m.npz"
    assert main(["pgd-build", str(path), "--out", str(out), "--modes", "2", "--quiet"]) == 0
    model: PGDModel = load_model(out, grid_shape=GRID)
    assert model.n_modes <= 2 and model.grid_shape == GRID
    assert "2 snapshots" in capsys.readouterr().out
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"manifold": {"electrode_x_m": [0.1], "typo": 1}}))
    assert main(["pgd-build", str(bad), "--out", str(out)]) == 2
    assert "unknown training-manifold keys" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["pgd-build", str(path), "--out", str(out), "--modes", "51"])
    graded = tmp_path / "graded.json"  # the default scene is graded: a PGD grid must be given
    graded.write_text(json.dumps({k: v for k, v in cfg.items() if k != "grid"}))
    assert main(["pgd-build", str(graded), "--out", str(out)]) == 2
    assert "graded grid (resolution)" in capsys.readouterr().err
