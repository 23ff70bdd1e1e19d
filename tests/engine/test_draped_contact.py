"""The draped contact disk follows a crater's surface: each quadrature point on the healthy
surface under it (a spherical bowl, within a cell), the whole current still j0 x area, and only
nodes of healthy tets loaded; on an uncut surface it is the flat disk exactly."""

from __future__ import annotations

import numpy as np
import pytest

from diathermy.engine.contact import draped_heights, weights_of
from diathermy.engine.simulation import Simulation
from diathermy.physics.contact_load import N_ANGULAR, N_RADIAL, disk_quadrature
from diathermy.physics.topology import healthy_tets

from .scenes import tiny_scene

A = 1.5e-3  # disk radius, m
BOWL_R, BOWL_DEPTH = 2.5e-3, 1.2e-3  # spherical crater: radius and depth at its centre, m


@pytest.fixture(scope="module")
def sim() -> Simulation:
    return Simulation(tiny_scene(grid=(41, 41, 41)))  # 0.5 / 0.25 / 0.25 mm cells


def bowl_phi(sim: Simulation) -> tuple[np.ndarray, np.ndarray]:
    """Level set of a spherical crater at the top centre, and the sphere's centre (m)."""
    p = sim.disc.mesh.points
    c = np.array([0.01, 0.005, sim.ctx.top_z + BOWL_R - BOWL_DEPTH])
    phi = np.minimum(sim.ctx.top_z - p[:, 2], np.linalg.norm(p - c, axis=1) - BOWL_R)
    return phi, c


def test_an_uncut_surface_gives_the_flat_disk(sim):
    top = sim.ctx.top_z
    phi = sim.disc.to_grid(top - sim.disc.mesh.points[:, 2])
    h = draped_heights(sim.disc, phi, np.zeros(sim.disc.n_tets, dtype=bool), 0.01, 0.005, A)
    assert np.all(h == top)
    flat = weights_of(sim.disc, (0.01, 0.005, top, A))
    drape = weights_of(sim.disc, (0.01, 0.005, top, A, *h))
    assert np.array_equal(flat.weights, drape.weights)


def test_the_disk_follows_a_spherical_bowl(sim):
    phi, c = bowl_phi(sim)
    healthy = healthy_tets(phi, sim.disc.mesh)
    h = draped_heights(sim.disc, sim.disc.to_grid(phi), ~healthy, 0.01, 0.005, A)
    pts, _ = disk_quadrature(np.array([0.01, 0.005, 0.0]), A, N_RADIAL, N_ANGULAR)
    r2 = (pts[:, 0] - c[0]) ** 2 + (pts[:, 1] - c[1]) ** 2
    exact = c[2] - np.sqrt(BOWL_R**2 - r2)  # the bowl's surface under each point (A < BOWL_R)
    dz = float(np.diff(sim.grid.axes()[2]).max())
    found = np.isfinite(h)
    assert found.mean() > 0.95, found.mean()  # nearly every point finds tissue under it
    assert np.all(np.abs(h - exact)[found] <= dz)  # within one cell layer of the bowl's surface
    assert np.nanmax(h) - np.nanmin(h) > 0.5 * (
        exact.max() - exact.min()
    )  # it follows the bowl's rise

    contact = weights_of(sim.disc, (0.01, 0.005, float(np.nanmin(h)), A, *h))
    kept = disk_quadrature(np.array([0.01, 0.005, 0.0]), A, N_RADIAL, N_ANGULAR)[1][np.isfinite(h)]
    assert contact.area_m2 == pytest.approx(kept.sum(), rel=1e-12)  # j0 x area: the current
    loaded = np.flatnonzero(contact.weights != 0)
    held = np.zeros(sim.disc.n_nodes, dtype=bool)
    held[sim.disc.mesh.tets[healthy].ravel()] = True
    assert held[loaded].all()  # no current into a node that only removed tissue touches


def test_points_over_a_hole_to_the_bottom_are_dropped(sim):
    """A column cut through to the bottom (the return electrode) carries no contact."""
    phi, _ = bowl_phi(sim)
    p = sim.disc.mesh.points
    hole = np.hypot(p[:, 0] - 0.0113, p[:, 1] - 0.005) < 1e-3
    phi = np.where(hole, -1e-3, phi)
    removed = ~healthy_tets(phi, sim.disc.mesh)
    h = draped_heights(sim.disc, sim.disc.to_grid(phi), removed, 0.01, 0.005, A)
    pts, w = disk_quadrature(np.array([0.01, 0.005, 0.0]), A, N_RADIAL, N_ANGULAR)
    gone = np.isnan(h)
    off_axis = np.hypot(pts[:, 0] - 0.0113, pts[:, 1] - 0.005)
    assert gone[off_axis < 5e-4].all()  # over the hole: nothing to touch
    assert gone[off_axis > 1.5e-3].mean() < 0.05  # away from it: the bowl as before
    contact = weights_of(sim.disc, (0.01, 0.005, float(np.nanmin(h)), A, *h))
    assert contact.area_m2 == pytest.approx(w[~gone].sum(), rel=1e-12)
