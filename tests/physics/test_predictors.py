"""Choosing the mechanics start (physics.predictors) on a small SPD system with known answer."""

from __future__ import annotations

import numpy as np

from diathermy.physics.predictors import choose_start, ritz_start


def _system(n: int = 12, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(3 * n, 3 * n))
    K = A @ A.T + 3 * n * np.eye(3 * n)
    u = rng.normal(size=(n, 3))
    return K, u, (K @ u.ravel()).reshape(n, 3)


def _matvec(K: np.ndarray):  # noqa: ANN202
    return lambda x: (K @ x.ravel()).reshape(-1, 3)


def test_ritz_start_recovers_a_multiple_of_the_answer() -> None:
    K, u, f = _system()
    free = np.ones_like(u, dtype=bool)
    s = ritz_start("previous", 2.0 * u, _matvec(K), f, free)
    assert np.isclose(s.ritz_scale, 0.5) and s.residual < 1e-12
    np.testing.assert_allclose(s.u, u, rtol=1e-12)


def test_choice_per_situation() -> None:
    K, u, f = _system()
    free = np.ones_like(u, dtype=bool)
    calls = []

    def exact() -> np.ndarray:
        calls.append(1)
        return u.copy()

    kw = dict(network_name="cnn", matvec=_matvec(K), f=f, free=free, switch_residual=0.5)
    # 'previous' with nothing before: no start (a full solve)
    c = choose_start("previous", u_prev=None, network=exact, **kw)
    assert c.start is None and "no previous" in c.why and not calls
    # 'auto', first step: the network
    c = choose_start("auto", u_prev=np.zeros_like(u), network=exact, **kw)
    assert c.start is not None and c.start.name == "cnn" and len(calls) == 1
    # steady: persistence close to the answer, the network not even asked
    near = u + 1e-3 * np.random.default_rng(1).normal(size=u.shape)
    c = choose_start("auto", u_prev=near, network=exact, **kw)
    assert c.start is not None and c.start.name == "previous" and len(calls) == 1
    assert "<=" in c.why
    # a jump: persistence far off (residual above the switch), the network nearer: the network
    far = np.random.default_rng(2).normal(size=u.shape)
    c = choose_start("auto", u_prev=far, network=exact, **kw)
    assert c.start is not None and c.start.name == "cnn" and c.considered["previous"] > 0.5
    # ...unless the network is farther still: persistence kept, both residuals reported
    noise = np.random.default_rng(3).normal(size=u.shape)
    off = u + 3.0 * np.linalg.norm(u) / np.linalg.norm(noise) * noise
    c = choose_start("auto", u_prev=off, network=lambda: noise, **kw)
    assert 0.5 < c.considered["previous"] < c.considered["cnn"], c.considered
    assert c.start is not None and c.start.name == "previous" and "kept" in c.why
    # no model: persistence, and the reason
    c = choose_start("auto", u_prev=far, network=None, unavailable="no network for grid 9x9x17",
                     **kw)  # fmt: skip
    assert c.start is not None and c.start.name == "previous" and "9x9x17" in c.why
