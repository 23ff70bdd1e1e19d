"""Greedy rank-one enrichment on synthetic separable tensors, against a slow reference."""

from __future__ import annotations

import numpy as np
import pytest

from diathermy.surrogates.pgd.offline import _contract, _outer, rank_one_enrichment


def test_contraction_matches_a_slow_loop() -> None:
    rng = np.random.default_rng(0)
    T = rng.normal(size=(5, 4, 3, 2))
    vecs = [rng.normal(size=d) for d in T.shape]
    for skip in range(4):
        ref = np.zeros(T.shape[skip])
        for idx in np.ndindex(*T.shape):
            w = np.prod([vecs[k][idx[k]] for k in range(4) if k != skip])
            ref[idx[skip]] += T[idx] * w
        np.testing.assert_allclose(_contract(T, vecs, skip), ref, rtol=1e-12)


def test_rank_one_function_is_reproduced_by_one_mode() -> None:
    x = np.linspace(0, 1, 40)
    vecs = [np.sin(np.pi * x) + x, np.exp(np.linspace(0, 1, 6)), np.linspace(1, 2, 3), [1.0, -0.5]]
    U = _outer([np.asarray(v) for v in vecs])
    enr = rank_one_enrichment(U, 5, tol=1e-12, fixed_point_tol=1e-14, max_fixed_point=200)
    assert enr.residual_history[0] < 1e-12
    assert len(enr.residual_history) == 1  # the stopping criterion ends the enrichment


def test_rank_three_function_needs_exactly_three_modes() -> None:
    """Orthogonal factors (sines on uniform grids): greedy rank-one recovers the rank exactly."""

    def sines(n: int, k: int) -> np.ndarray:
        j = np.arange(1, n + 1)
        return np.sin(np.pi * k * j / (n + 1))

    dims = (50, 7, 5, 4)
    U = sum(amp * _outer([sines(d, k) for d in dims]) for amp, k in ((3.0, 1), (2.0, 2), (1.0, 3)))
    enr = rank_one_enrichment(U, 6, tol=1e-10, fixed_point_tol=1e-14, max_fixed_point=500)
    hist = enr.residual_history
    assert hist[1] > 0.1  # two modes are not enough
    assert hist[2] < 1e-8  # the third closes it
    assert len(hist) == 3


def test_residual_never_increases_and_factors_are_unit() -> None:
    rng = np.random.default_rng(1)
    U = rng.normal(size=(30, 4, 3, 3))
    enr = rank_one_enrichment(U, 12, tol=1e-14)
    h = np.array(enr.residual_history)
    assert np.all(np.diff(h) <= 1e-12)
    for f in enr.factors[1:]:
        np.testing.assert_allclose(np.linalg.norm(f, axis=1), 1.0)


def test_zero_tensor_is_refused() -> None:
    with pytest.raises(ValueError, match="zero"):
        rank_one_enrichment(np.zeros((3, 2, 2, 2)), 2)
