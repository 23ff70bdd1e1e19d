"""The dataset generator runs the engine's physics: the same (p, phi, W) give the same
displacement, strain energy, level set and topology in both (Algorithm 1 = the engine's step)."""

from __future__ import annotations

import dataclasses

import numpy as np

from diathermy.datagen import DatagenConfig
from diathermy.datagen.physics import fem_physics
from diathermy.engine.backends import fem_of
from diathermy.engine.effects import mechanics
from diathermy.engine.pipeline import begin_step
from diathermy.engine.simulation import Simulation
from diathermy.fem.solvers import ReuseState
from tests.engine.scenes import tiny_scene


def _pair(reinit_every: int) -> tuple[Simulation, DatagenConfig]:
    scene = tiny_scene(level_set={"reinit_every": reinit_every})
    config = DatagenConfig(
        grid=scene.grid,
        block_m=scene.block_m,
        material=scene.material,
        dt_s=scene.dt_s,
        level_set=scene.level_set,
        mechanics_rtol=scene.mechanics.rtol,
        n_scenarios=1,
        n_steps=1,
    )
    return Simulation(scene), config


def test_engine_and_generator_cut_alike_step_by_step():
    """Feed the generator the engine's (phi, W) of every step of a cutting run: it returns the
    engine's next level set bit for bit, and its healthy rule gives the engine's removed tets,
    re-initialisation schedule included (every 3 dissection steps here)."""
    sim, config = _pair(reinit_every=3)
    gen = fem_physics(config)
    moved = reinits = 0
    for step in range(40):
        phi = sim.state["level_set"].copy()
        sim.step()
        diss = sim.last_report.effects["dissection"]
        moved += diss.ran
        reinits += diss.ran and diss.extra["reinitialized"]
        W = sim.state["strain_energy"]
        new_phi = gen.advance(phi, W, step)
        assert np.array_equal(new_phi, sim.state["level_set"]), step
        assert np.array_equal(~gen.healthy_tets(new_phi), sim.state["removed"]), step
    assert moved >= 6 and reinits >= 2 and sim.state["removed"].any()


def test_engine_and_generator_solve_the_same_mechanics():
    """Same pressure and cut: the same displacement and strain energy (no warm start in either)."""
    sim, config = _pair(reinit_every=10)
    sim.run(30)
    assert sim.state["removed"].any() and np.any(sim.state["pressure"] != config.material.p_atm_pa)
    gen = fem_physics(config)
    u_gen, W_gen = gen.solve(sim.state["pressure"], sim.state["level_set"])
    state = dataclasses.replace(sim.state, arrays=dict(sim.state.arrays))
    state["displacement"] = np.zeros_like(state["displacement"])
    # the engine keeps its AMG hierarchy across cuts; built afresh, it is the generator's
    backend = fem_of(sim.ctx.mechanics)
    assert backend is not None and backend.krylov.n_setups < backend.n_builds
    backend.krylov.reuse = ReuseState(rebuild_due=True)
    out = mechanics.run(sim.ctx, state, begin_step(sim.ctx, state))
    u, W = out.fields["displacement"], out.fields["strain_energy"]
    np.testing.assert_allclose(u_gen, u, rtol=0, atol=1e-12 * np.abs(u).max())
    np.testing.assert_allclose(W_gen, W, rtol=0, atol=1e-10 * W.max())
