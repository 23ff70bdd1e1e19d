"""The lean V-cycle is pyamg's V-cycle preconditioner, minus the bookkeeping."""

from __future__ import annotations

import numpy as np
import pyamg

from diathermy.fem.multigrid import v_cycle_preconditioner


def test_v_cycle_equals_pyamg_preconditioner(rng):
    A = pyamg.gallery.poisson((16, 16, 16), format="csr")
    for options in (
        {},
        {"presmoother": ("chebyshev", {"degree": 2}), "postsmoother": ("chebyshev", {"degree": 2})},
    ):
        ml = pyamg.smoothed_aggregation_solver(A, max_coarse=20, **options)
        assert len(ml.levels) >= 3
        b = rng.normal(size=A.shape[0])
        ref = ml.aspreconditioner(cycle="V") @ b
        assert np.allclose(
            v_cycle_preconditioner(ml) @ b, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max()
        )
