"""``level_set.removal`` 'fraction': the properties of a partly cut tet blend by its tissue share,
so the displacement and the cut's driver are continuous in the level set, where the half-volume
threshold makes them jump when a tet's removed fraction crosses 0.5."""

from __future__ import annotations

import numpy as np
import pytest

from diathermy.fem.geometry import element_geometry
from diathermy.mesh import Grid, build_tet_mesh
from diathermy.physics.dissection import cut_driver
from diathermy.physics.materials import ersatz_youngs_modulus, share_blend
from diathermy.physics.mechanics import MechanicsSolver
from diathermy.physics.strain_energy import strain_energy_density
from diathermy.physics.topology import Topology, evaluate_topology, tissue_share

E, NU, RATIO, DP = 0.27e6, 0.4, 1e-6, 2e4
GRID = Grid((7, 7, 9), size_m=(0.01, 0.01, 0.01))


@pytest.fixture(scope="module")
def mesh():
    return build_tet_mesh(GRID)


def topology_at(mesh, c: float) -> Topology:
    """The cut of everything above the plane z = c (phi = c - z < 0 there)."""
    volumes = element_geometry(mesh.points, mesh.tets).volumes
    return evaluate_topology(c - mesh.points[:, 2], mesh, volumes)


def switch_height(mesh) -> float:
    """A plane height (m) where tets' removed fraction crosses 0.5: bisected to ~1e-15 m
    between two heights whose removed masks differ."""
    dz = GRID.size_m[2] / (GRID.shape[0] - 1)
    lo, hi = 0.5 * GRID.size_m[2] + 0.1 * dz, 0.5 * GRID.size_m[2] + 0.9 * dz
    a = topology_at(mesh, lo).removed
    assert not np.array_equal(a, topology_at(mesh, hi).removed)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if np.array_equal(topology_at(mesh, mid).removed, a):
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def fields(mesh, topo: Topology, removal: str) -> tuple[np.ndarray, np.ndarray]:
    """(u (n_nodes, 3) m under a uniform pore overpressure, the cut's nodal driver W J/m^3)."""
    healthy = ~topo.removed if removal == "threshold" else tissue_share(topo.fraction, topo.loose)
    Es = ersatz_youngs_modulus(healthy, E, RATIO)
    solver = MechanicsSolver(mesh, Es, NU, healthy=healthy, rtol=1e-12, maxiter=2000)
    u = solver.solve(np.full(mesh.n_nodes, 101325.0 + DP)).u
    geom = solver.assembler.geom
    W = strain_energy_density(geom.grads, mesh.tets, u, Es, NU)
    share = None if removal == "threshold" else healthy
    W_nodes = cut_driver(
        W,
        topo.removed,
        mesh=mesh,
        grid=GRID,
        volumes=geom.volumes,
        incidence=None,
        length_m=0.0,
        tissue_share=share,
    )
    return u, W_nodes


def test_the_share_is_the_tissue_left_and_zero_in_loose_fragments():
    fraction = np.array([0.0, 0.25, 0.5, 1.0])
    loose = np.array([False, False, False, True])
    topo = Topology(fraction, fraction >= 0.5, loose, 0.0, 0.0)
    assert np.array_equal(tissue_share(topo.fraction, topo.loose), [1.0, 0.75, 0.5, 0.0])
    assert topo.fraction[3] == 1.0  # the topology's own arrays are not written
    # the blend's ends are the two materials exactly; the middle is linear
    assert np.array_equal(share_blend(np.array([1.0, 0.0, 0.5]), 4.0, 2.0), [4.0, 2.0, 3.0])
    assert np.array_equal(ersatz_youngs_modulus(np.array([True, False]), E, RATIO), [E, RATIO * E])
    assert np.array_equal(ersatz_youngs_modulus(np.array([1.0, 0.0]), E, RATIO), [E, RATIO * E])


@pytest.mark.parametrize("removal", ["threshold", "fraction"])
def test_displacement_and_driver_across_the_removal_threshold(mesh, removal):
    """Moving the plane by 2e-12 m across the height where a layer of tets passes half removed:
    the threshold switches those tets (96 here) to ersatz material and u and W jump by tens of
    percent; the fraction blend changes their shares by ~1e-12 m / 1.7 mm, and u and W as little."""
    c = switch_height(mesh)
    below, above = topology_at(mesh, c - 1e-12), topology_at(mesh, c + 1e-12)
    flipped = int(np.count_nonzero(below.removed != above.removed))
    assert flipped >= 4
    u0, W0 = fields(mesh, below, removal)
    u1, W1 = fields(mesh, above, removal)
    du = np.linalg.norm(u1 - u0) / np.linalg.norm(u0)
    dW = np.abs(W1 - W0).max() / np.abs(W0).max()
    if removal == "threshold":
        assert du > 0.1 and dW > 0.5  # measured 0.35 and 1.0
    else:
        assert du < 1e-8 and dW < 1e-7  # measured 7e-11 and 1.6e-9


def test_whole_tets_give_the_threshold_answer_bit_for_bit(mesh):
    """A plane on a node layer leaves every tet whole or gone (fraction 0 or 1): the blend is
    then the threshold rule exactly, to the bit."""
    dz = GRID.size_m[2] / (GRID.shape[0] - 1)
    topo = topology_at(mesh, 4 * dz)
    assert set(np.unique(topo.fraction)) == {0.0, 1.0}
    u_t, W_t = fields(mesh, topo, "threshold")
    u_f, W_f = fields(mesh, topo, "fraction")
    assert np.array_equal(u_t, u_f) and np.array_equal(W_t, W_f)
