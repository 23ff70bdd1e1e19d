"""The electric problem on graded grids (issue #21): exact contact current, the half-space
potential law, and the delivered power converging to the resolved-contact value."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate, special

from diathermy.fem.edges import edge_stiffness
from diathermy.fem.geometry import structured_geometry
from diathermy.mesh import Grid, TetMesh, build_tet_mesh
from diathermy.physics.contact_load import contact_weights
from diathermy.physics.contact_resistance import (
    block_image_resistance,
    equipotential_disk_resistance,
    uniform_flux_disk_resistance,
)
from diathermy.physics.driven_potential import DrivenPotential, ElectrodeDrive
from diathermy.physics.electric import PotentialSolver

A_M, J0, SIGMA = 1.17e-3, 5.72e4, 0.33
CENTRE = (0.1, 0.05, 0.1)
BOX = ((0.097, 0.047, 0.097), (0.103, 0.053, 0.1))  # the contact +- 3 mm, 3 mm deep


def graded_mesh(fine_m: float) -> TetMesh:
    return build_tet_mesh(Grid.graded(*BOX, fine_m, growth=1.25, max_cell_m=6.25e-3))


@pytest.fixture(scope="module")
def mesh_1mm() -> TetMesh:
    return graded_mesh(1e-3)


def solve(mesh: TetMesh):  # noqa: ANN201
    geom = structured_geometry(mesh.points, mesh.tets, mesh.shape_id)
    solver = PotentialSolver(mesh, edge_stiffness(geom, mesh.tets, mesh.n_nodes))
    return DrivenPotential(solver).solve(
        SIGMA, contact_weights(mesh, CENTRE, A_M), ElectrodeDrive()
    )


@pytest.mark.parametrize(
    "centre",
    [CENTRE, (0.1032, 0.0529, 0.1), (0.06, 0.02, 0.1)],
    ids=["fine cells", "across the fine/graded edge", "coarse cells"],
)
def test_injected_current_is_exact_on_a_graded_grid(mesh_1mm, centre):
    c = contact_weights(mesh_1mm, centre, A_M)
    assert c.weights.sum() == pytest.approx(np.pi * A_M**2, rel=1e-12)
    assert np.all(c.weights >= 0)
    moment = c.weights @ mesh_1mm.points
    assert np.allclose(moment, c.area_m2 * np.asarray(centre), rtol=1e-12)


def test_half_space_potential_law_on_a_graded_grid(mesh_1mm):
    """V(r1) - V(r2) on the top surface against I/(2 pi sigma r) (1 + a^2/(8 r^2)) and the
    grounded bottom's images: within 1 % at r1 = 5.7 mm, r2 = 31 mm (measured 0.1 %) and at
    r1 = 9.8 mm, r2 = 50 mm, where the uniform 33x33x65 grid needs 5 % at 15.6 / 40.6 mm."""
    sol = solve(mesh_1mm)
    H = mesh_1mm.grid.size_m[2]

    def half_space(r: float) -> float:
        k = np.arange(1, 60)
        images = np.sum((-1.0) ** k * 2.0 / np.sqrt(r**2 + (2 * k * H) ** 2))
        return sol.current_a / (2 * np.pi * SIGMA) * ((1 + A_M**2 / (8 * r**2)) / r + images)

    top = mesh_1mm.side_nodes("z+")
    row = top[np.abs(mesh_1mm.points[top, 1] - CENTRE[1]) < 1e-9]
    x = mesh_1mm.points[row, 0] - CENTRE[0]
    for r1, r2 in ((0.0057, 0.031), (0.0098, 0.05)):
        i1, i2 = row[np.argmin(np.abs(x - r1))], row[np.argmin(np.abs(x - r2))]
        R1, R2 = (mesh_1mm.points[i, 0] - CENTRE[0] for i in (i1, i2))
        assert sol.V[i1] - sol.V[i2] == pytest.approx(half_space(R1) - half_space(R2), rel=0.01)


def test_delivered_power_converges_to_the_resolved_contact():
    """P under the current-density drive rises toward 8 I^2/(3 pi^2 sigma a) + block (42.5 W):
    1 mm and 0.5 mm cells under the contact give 33.2 and 39.1 W (uniform 33x33x65: 20.5 W)."""
    current = J0 * np.pi * A_M**2
    ref = current**2 * (
        uniform_flux_disk_resistance(SIGMA, A_M)
        + block_image_resistance(SIGMA, (0.2, 0.1, 0.1), (0.0, 0.0, 0.0), CENTRE[:2])
    )
    p = [solve(graded_mesh(h)).power_w for h in (1e-3, 0.5e-3)]
    assert p[0] < p[1] < ref
    assert p[1] == pytest.approx(ref, rel=0.1)


def test_uniform_flux_disk_resistance_matches_its_integral():
    """<V> of a uniform current density on a disk: V(rho) = 2 j a E(rho/a) / (pi sigma) inside
    (E the complete elliptic integral of the second kind), averaged over the disk."""
    j = 1.0 / (np.pi * A_M**2)  # 1 A

    def v(rho: float) -> float:
        return 2 * j * A_M * special.ellipe((rho / A_M) ** 2) / (np.pi * SIGMA)

    assert v(0.0) == pytest.approx(j * A_M / SIGMA)  # the centre: j a / sigma
    mean, _ = integrate.quad(lambda r: v(r) * 2 * np.pi * r, 0.0, A_M)
    mean /= np.pi * A_M**2
    assert mean == pytest.approx(uniform_flux_disk_resistance(SIGMA, A_M), rel=1e-8)
    ratio = uniform_flux_disk_resistance(SIGMA, A_M) / equipotential_disk_resistance(SIGMA, A_M)
    assert ratio == pytest.approx(32 / (3 * np.pi**2))  # 8 % above the equipotential disk


def test_block_images_reduce_to_the_grounded_slab_and_converge():
    """A laterally huge block: only the bottom's images, -ln 2 / (2 pi sigma H)."""
    wide = block_image_resistance(SIGMA, (100.0, 100.0, 0.1), (0.0, 0.0, 0.0), (50.0, 50.0))
    assert wide == pytest.approx(-np.log(2) / (2 * np.pi * SIGMA * 0.1), rel=1e-4)
    paper = [
        block_image_resistance(SIGMA, (0.2, 0.1, 0.1), (0.0, 0.0, 0.0), CENTRE[:2], **kw)
        for kw in ({}, {"n_lateral": 16, "n_vertical": 1000})
    ]
    assert paper[0] == pytest.approx(paper[1], rel=2e-3) and paper[0] > 0
