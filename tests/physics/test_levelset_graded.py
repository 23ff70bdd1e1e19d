"""The level set on graded grids: plane fronts move at F, the CFL limit is the local one, the
scheme equals the uniform one on a uniform grid, and re-initialisation restores a distance."""

from __future__ import annotations

import numpy as np

from diathermy.mesh import Grid
from diathermy.mesh.grading import graded_axis
from diathermy.physics.levelset import advance, grid_spacing, reinitialize


def graded_column(fine: float = 2e-4) -> Grid:
    """1 cm deep, fine over the top 3 mm, growing 1.3x below; a few columns wide."""
    z = graded_axis(0.0, 0.01, (0.007, 0.01), fine, 1.3, 2e-3)
    return Grid.from_axes(np.linspace(0, 0.004, 5), np.linspace(0, 0.003, 4), z)


def crossings(phi: np.ndarray, z: np.ndarray) -> np.ndarray:
    """z where phi (positive below) changes sign downward, per column."""
    col = phi.reshape(phi.shape[0], -1)
    k = np.clip(np.argmin(col > 0, axis=0) - 1, 0, z.size - 2)
    a, b = col[k, np.arange(col.shape[1])], col[k + 1, np.arange(col.shape[1])]
    return z[k] + (z[k + 1] - z[k]) * a / (a - b)


def test_plane_moves_down_at_constant_speed_across_the_grading():
    g = graded_column()
    z = g.axes()[2]
    F, t, z0 = 2e-3, 2.0, 0.0095  # from the fine layer down into the growing cells (5.5 mm)
    phi0 = np.broadcast_to((z0 - z)[:, None, None], g.shape)
    step = advance(phi0, np.full(g.shape, F), grid_spacing(g), t)
    assert np.abs(crossings(step.phi, z) - (z0 - F * t)).max() < 1e-9  # exact for a plane
    assert np.all(step.phi <= phi0)


def test_cfl_is_the_local_one():
    g = graded_column()
    z = g.axes()[2]
    phi0 = np.broadcast_to((0.003 - z)[:, None, None], g.shape).copy()
    F = np.zeros(g.shape)
    F[z < 0.004] = 1e-3  # only in the coarse cells (>= 0.2 mm x 1.3^k)
    coarse = advance(phi0, F, grid_spacing(g), 1.0)
    F_fine = np.zeros(g.shape)
    F_fine[z > 0.0095] = 1e-3
    fine = advance(phi0, F_fine, grid_spacing(g), 1.0)
    assert coarse.n_substeps < fine.n_substeps
    dz_fine = np.diff(z).min()
    rate = 1e-3 * (1 / 1e-3 + 1 / 1e-3 + 1 / dz_fine)  # x, y cells are 1 mm
    assert fine.n_substeps == int(np.ceil(1.0 * rate / 0.5))


def test_graded_scheme_equals_the_uniform_one_on_a_uniform_grid():
    g = Grid((9, 7, 8), size_m=(0.007, 0.006, 0.008))
    rng = np.random.default_rng(3)
    phi = rng.normal(size=g.shape) * 1e-3
    F = rng.uniform(0, 2e-3, size=g.shape)
    uniform = advance(phi, F, g.spacing_m, 0.3)
    as_graded = advance(phi, F, g.cell_sizes_m(), 0.3)
    assert uniform.n_substeps == as_graded.n_substeps
    assert np.allclose(uniform.phi, as_graded.phi, rtol=0, atol=1e-15)


def test_reinitialize_on_a_graded_grid_restores_a_distance():
    x = graded_axis(0.0, 0.02, (0.008, 0.012), 2.5e-4, 1.25, 2e-3)
    g = Grid.from_axes(x, x, x)
    c = np.array([0.0101, 0.0098, 0.0102])
    d = np.linalg.norm(g.points().reshape(g.shape + (3,)) - c, axis=-1) - 0.0015
    phi = np.where(d > 0, 2.5 * d, 0.4 * d)
    new = reinitialize(phi, grid_spacing(g))
    assert np.array_equal(np.sign(new), np.sign(phi))  # removed stays removed, healthy healthy
    near = (np.abs(d) < 4 * 2.5e-4) & (phi > 0)
    assert np.all(new[near] <= phi[near] + 1e-15)  # never raised next to the front
    # the steep healthy side is back to a distance: first order in the fine spacing
    assert np.abs(new[near] - d[near]).max() < 2.5e-4
    deep = (d < -4e-4) & (d > -1e-3)
    assert np.abs(new[deep] - d[deep]).max() < 2.5e-4  # the shallow removed side too
