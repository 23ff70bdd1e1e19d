"""How far a nodal set reaches beyond the working region (``engine.fine_region``), against the
node-by-node definition on uniform and graded grids."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from diathermy.engine.fine_region import beyond_fine_region, box_excess_m
from diathermy.mesh import Grid

SIZE = (0.02, 0.01, 0.01)


def brute_excess(grid: Grid, mask: np.ndarray, box) -> float:
    """The largest excess beyond the box of any masked node along any axis."""
    pts = grid.points()[mask.ravel()]
    if pts.size == 0:
        return 0.0
    lo, hi = np.asarray(box[0]), np.asarray(box[1])
    return float(max(0.0, (lo - pts).max(), (pts - hi).max()))


corner = st.tuples(*(st.floats(0.0, 1.0) for _ in range(3)))


@settings(max_examples=60, deadline=None)
@given(
    graded=st.booleans(),
    a=corner,
    b=corner,
    density=st.floats(0.0, 0.2),
    seed=st.integers(0, 2**16),
)
def test_excess_is_the_farthest_masked_node_beyond_the_box(graded, a, b, density, seed):
    lo = tuple(min(u, v) * s for u, v, s in zip(a, b, SIZE, strict=True))
    hi = tuple(max(u, v) * s for u, v, s in zip(a, b, SIZE, strict=True))
    if graded:
        grid = Grid.graded(lo, hi, 1e-3, growth=1.5, max_cell_m=4e-3, size_m=SIZE)
    else:
        grid = Grid((7, 9, 11), size_m=SIZE)
    mask = np.random.default_rng(seed).random(grid.n_nodes) < density
    got = box_excess_m(grid, mask, (lo, hi))
    want = brute_excess(grid, mask, (lo, hi))
    assert got == (want if want > 1e-9 * max(SIZE) else 0.0)


def test_nodes_on_the_box_face_are_inside():
    grid = Grid.graded((0.008, 0.003, 0.008), (0.012, 0.007, 0.01), 5e-4, size_m=SIZE)
    x, y, z = grid.axes()
    box = ((x[0], y[0], z[0]), (x[-1], y[-1], z[-1]))
    assert box_excess_m(grid, np.ones(grid.n_nodes, dtype=bool), box) == 0.0


def test_cut_vapor_and_lesion_are_measured_apart():
    grid = Grid((5, 5, 5), size_m=(0.004, 0.004, 0.004))  # 1 mm cells
    z = grid.points()[:, 2]
    phi = z - 0.0025  # removed below 2.5 mm: the nodes at 0, 1, 2 mm
    vapor = np.where(z >= 0.003, 0.1, 0.0)  # vapor in the top two layers
    omega = np.where(np.isclose(z, 0.001), 1.0, 0.99)  # the lesion's edge is Omega = 1
    box = ((0.0, 0.0, 0.0015), (0.004, 0.004, 0.004))
    got = beyond_fine_region(grid, box, phi, vapor, omega)
    assert got == {"cut": 0.0015, "vapor": 0.0, "lesion": 0.0005}
    assert beyond_fine_region(grid, None, phi, vapor, omega) == {}
