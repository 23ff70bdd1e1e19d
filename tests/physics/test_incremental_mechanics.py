"""The local path of the incremental mechanics: patch rounds continue where the last one left
off, lower the residual, and stop once the guard is met."""

from __future__ import annotations

import numpy as np

from diathermy.mesh import Grid, build_tet_mesh
from diathermy.physics.local_solve import IncrementalSettings, local_solve
from diathermy.physics.mechanics import MechanicsSolver
from diathermy.physics.patch_correction import node_graph
from diathermy.physics.predictors import ritz_start

E, NU, P0 = 0.27e6, 0.4, 101325.0


def _setup():
    mesh = build_tet_mesh(Grid((9, 9, 17)))
    c = mesh.centroids()
    healthy = np.linalg.norm(c - [0.1, 0.05, 0.1], axis=1) > 0.02
    solver = MechanicsSolver(mesh, np.where(healthy, E, 1e-6 * E), NU, healthy=healthy)
    r = np.linalg.norm(mesh.points - [0.1, 0.05, 0.1], axis=1)
    p1 = P0 + 2e5 * np.exp(-((r / 0.03) ** 2))
    p2 = P0 + 2.4e5 * np.exp(-((r / 0.028) ** 2))  # hotter and narrower: not a multiple of p1
    u1 = solver.solve(p1).u
    return solver, u1, p2, node_graph(solver.K)


def _local(solver, u1, p2, graph, settings):  # noqa: ANN001, ANN202
    """The local path from persistence: u1 Ritz-scaled on p2's system, then patched."""
    f = solver.load(p2, P0).reshape(-1, 3)
    free = ~solver.constrained.reshape(-1, 3)
    start = ritz_start("previous", u1, lambda u: (solver.K @ u.ravel()).reshape(-1, 3), f, free)
    return local_solve(solver, start, f, graph, settings, u1)


def test_patch_rounds_lower_the_residual_and_stop_at_the_guard():
    solver, u1, p2, graph = _setup()
    tight = IncrementalSettings(guard_tolerance=1e-12, patch_rounds=1)
    one = _local(solver, u1, p2, graph, tight)
    three = _local(solver, u1, p2, graph, IncrementalSettings(1e-12, patch_rounds=3))
    assert one.residual < one.residual_before and three.residual_before == one.residual_before
    assert three.residual < 0.7 * one.residual  # the later rounds catch what the first left
    assert np.isin(one.patch_nodes, three.patch_nodes).all()
    assert three.patch_nodes.size > one.patch_nodes.size
    # a guard that the first round meets: the later rounds do not run
    loose = IncrementalSettings(guard_tolerance=1.01 * one.residual, patch_rounds=3)
    met = _local(solver, u1, p2, graph, loose)
    assert met.residual == one.residual and np.array_equal(met.patch_nodes, one.patch_nodes)
    np.testing.assert_array_equal(met.u, one.u)


def test_scene_defaults_are_the_solver_defaults():
    """The scene model states the incremental knobs' defaults; they are the solver's own."""
    from diathermy.physics.local_solve import IncrementalSettings
    from diathermy.scene.models import MechanicsConfig

    cfg, settings = MechanicsConfig(), IncrementalSettings()
    assert cfg.energy_tolerance == settings.energy_tolerance
    assert cfg.polish_iterations == settings.polish_iterations
    assert cfg.polish_window_m == settings.window_m
