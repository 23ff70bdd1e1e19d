"""The mechanics predictor per situation (issue #22): 'auto' takes the network where persistence
has nothing (the first mechanics step) and persistence in steady stepping and after a power
jump, as benchmarks/results/predictors.md measured; every step report names the predictor; a
grid without a model falls back to persistence with the reason in the report, never an error."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diathermy.engine.simulation import Simulation
from diathermy.physics.incremental_mechanics import IncrementalFEMBackend
from diathermy.physics.strain_energy import relative_strain_energy_error
from diathermy.scene import SolverConfig
from tests.engine.scenes import tiny_scene
from tests.surrogates.hybrid_helpers import untrained_model


def _mechanics_steps(sim: Simulation, n: int) -> list[dict]:
    """The mechanics reports' extras of the next n steps whose mechanics ran."""
    out: list[dict] = []
    for _ in range(60):
        mech = sim.step().effects["mechanics"]
        if mech.ran:
            out.append(mech.extra)
            if len(out) == n:
                break
    return out


def test_auto_picks_the_network_first_and_persistence_after(tmp_path: Path) -> None:
    model = untrained_model(tmp_path / "net.pt")
    sim = Simulation(tiny_scene(mechanics={"predictor": "auto", "model": str(model)}))
    backend = sim.ctx.mechanics
    assert isinstance(backend, IncrementalFEMBackend) and backend.network is not None
    first, *steady = _mechanics_steps(sim, 6)
    assert first["predictor"] == "cnn", first
    assert "no previous displacement" in first["predictor_why"]
    # steady stepping: persistence, and why (its residual is small)
    for extra in steady:
        if extra["why"].startswith("interval"):
            continue
        assert extra["predictor"] == "previous", extra
        assert "persistence residual" in extra["predictor_why"]
    # a power jump: persistence still (measured: it keeps the lower error there)
    sim.set_electrode(sim.scene.electrodes[0].name, power_w=3 * sim.scene.electrodes[0].power_w)
    jump = _mechanics_steps(sim, 1)[0]
    assert jump["predictor"] == "previous" and "<=" in jump["predictor_why"], jump
    assert backend.network.n_predictions >= 1  # type: ignore[union-attr]


def test_auto_without_a_model_runs_on_persistence_and_says_why() -> None:
    """No model for the 9x9x17 grid: 'auto' runs on persistence, saying why, and its answers
    are those of 'previous' step for step."""
    auto = Simulation(tiny_scene(mechanics={"predictor": "auto"}))
    prev = Simulation(tiny_scene())
    full = Simulation(tiny_scene(solver=SolverConfig(incremental=False)))
    backend = auto.ctx.mechanics
    assert isinstance(backend, IncrementalFEMBackend) and backend.network is None
    assert "no network for grid 9x9x17" in (backend.network_unavailable or "")
    seen_first = False
    for _ in range(24):
        ra, rp, _ = auto.step(), prev.step(), full.step()
        ma = ra.effects["mechanics"]
        if not ma.ran:
            continue
        if not seen_first:
            assert ma.extra["mode"] == "full" and ma.extra["predictor"] == "none"
            assert "no network for grid 9x9x17" in ma.extra["why"]
            seen_first = True
        else:
            assert ma.extra["predictor"] == "previous"
        assert rp.effects["mechanics"].extra["predictor"] == ma.extra["predictor"]
        np.testing.assert_array_equal(auto.state["displacement"], prev.state["displacement"])
        W, W_ref = auto.state["strain_energy"], full.state["strain_energy"]
        assert relative_strain_energy_error(W, W_ref) <= 0.01
    assert seen_first


def test_reports_name_the_predictor_of_every_backend() -> None:
    full = Simulation(tiny_scene(solver=SolverConfig(incremental=False)))
    prev = Simulation(tiny_scene())
    alone = Simulation(tiny_scene(mechanics={"correction": "none", "guard_tolerance": 1.0}))
    for sim, allowed in ((full, {"none"}), (prev, {"none", "previous"}),
                         (alone, {"none", "previous"})):  # fmt: skip
        names = {e["predictor"] for e in _mechanics_steps(sim, 8)}
        assert names <= allowed and names, names
    # persistence without the patch (mechanics.correction 'none'): no patch on its local steps
    local = 0
    for _ in range(8):
        mech = alone.step().effects["mechanics"]
        if mech.ran and mech.extra["mode"] == "local":
            assert mech.extra["patch_nodes"] == 0
            local += 1
    assert local > 0
