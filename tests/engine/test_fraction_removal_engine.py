"""The engine under ``level_set.removal`` 'fraction' (each tet's properties blended by its tissue
share): it cuts, closes its energy balance, blends the conductivity of partly cut tets, is the
threshold model to the bit until the first cut, finds the shares without its topology in memory
and restores bit for bit."""

from __future__ import annotations

import numpy as np

from diathermy.engine.backends import fem_of
from diathermy.engine.effects.electric import conductivity
from diathermy.engine.effects.thermal import heat_conductivity
from diathermy.engine.removal import tissue_share
from diathermy.engine.simulation import Simulation
from tests.engine.test_graded_engine import graded_scene

FRACTION = {"removal": "fraction"}


def test_a_fraction_run_cuts_balances_energy_and_blends_partly_cut_tets():
    sim = Simulation(graded_scene(level_set=FRACTION))
    reports = sim.run(25)
    cut = [r.cut_volume_m3 for r in reports]
    assert cut[-1] > 0 and all(b >= a for a, b in zip(cut, cut[1:], strict=False))
    e = reports[-1].energy
    assert abs(e["imbalance"]) <= 1e-3 * e["joule_in"]
    share = tissue_share(sim.ctx, sim.state)
    assert share is not None
    partial = (share > 0) & (share < 1)
    assert partial.any()
    sigma = conductivity(sim.ctx, sim.state)
    t = sim.ctx.tissue
    whole = share == 1
    # a partly cut tet conducts between removed tissue and the tissue's own (its share's blend)
    assert np.all(sigma[partial] > t.sigma_removed_s_per_m)
    assert np.all(sigma[partial] < sigma[whole].max())
    assert np.all(sigma[share == 0] == t.sigma_removed_s_per_m)
    # heat conduction likewise, between vapor's and the mixture's
    k = heat_conductivity(sim.ctx, sim.state)
    lo, hi = sorted((t.k_vapor_w_per_m_k, float(k[whole].max())))
    assert np.all((k[partial] > lo) & (k[partial] < hi))
    assert np.all(k[share == 0] == t.k_vapor_w_per_m_k)
    # and the stiffness the mechanics solved with (the shares of the step before the last
    # advance): blended between ersatz and the tissue's, where the threshold has only the two
    E = fem_of(sim.mechanics).solver.youngs_modulus_pa
    E_t, ersatz = t.youngs_modulus_pa, t.ersatz_stiffness_ratio * t.youngs_modulus_pa
    assert np.count_nonzero((E > 1.001 * ersatz) & (E < 0.999 * E_t)) > 10


def test_without_the_topology_the_shares_come_from_the_level_set_exactly():
    """A state restored without the dissection's topology (memory) gets the same shares from
    its level set and removed mask: the removed tets not half cut are the loose ones."""
    sim = Simulation(graded_scene(level_set=FRACTION))
    sim.run(20)
    kept = tissue_share(sim.ctx, sim.state)
    assert kept is not None and (kept < 1).any()
    sim.state.memory.topology = None
    again = tissue_share(sim.ctx, sim.state)
    assert again is not None and np.array_equal(again, kept)
    assert tissue_share(Simulation(graded_scene()).ctx, sim.state) is None  # threshold


def test_a_fraction_run_differs_from_a_threshold_run_only_once_tets_are_partly_cut():
    """Before the cut the two removal rules are one model: the same fields to the bit."""
    thr = Simulation(graded_scene())
    frac = Simulation(graded_scene(level_set=FRACTION))
    for _ in range(25):
        thr.step()
        frac.step()
        if thr.topology is not None and thr.topology.cut_volume_m3 > 0:
            break
        for name, arr in thr.state.arrays.items():
            assert np.array_equal(arr, frac.state.arrays[name]), name
    else:
        raise AssertionError("the tiny graded scene did not cut in 25 steps")


def test_a_fraction_checkpoint_restores_bit_for_bit(tmp_path):
    sim = Simulation(graded_scene(level_set=FRACTION))
    sim.run(12)
    path = sim.save_checkpoint(tmp_path / "c.h5")
    sim.run(5)
    back = Simulation.load_checkpoint(path)
    assert back.scene.level_set.removal == "fraction"
    back.run(5)
    for name, arr in sim.state.arrays.items():
        assert np.array_equal(arr, back.state.arrays[name]), name
