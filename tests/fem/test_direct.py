"""The SPD factorisation of small blocks: exact solves, and singular blocks refused."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from diathermy.fem.direct import spd_factor


def _laplacian_3d(n: int) -> sp.csr_matrix:
    one = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])
    eye = sp.identity(n)
    return (
        sp.kron(sp.kron(one, eye), eye)
        + sp.kron(sp.kron(eye, one), eye)
        + sp.kron(eye, sp.kron(eye, one))
    ).tocsr()


def test_solves_an_spd_block_to_round_off(rng):
    A = _laplacian_3d(9)  # 729 unknowns, the grid Laplacian with Dirichlet walls
    x = rng.standard_normal(A.shape[0])
    got = spd_factor(A).solve(A @ x)
    assert np.abs(got - x).max() < 1e-10 * np.abs(x).max()


def test_a_singular_block_is_refused():
    A = _laplacian_3d(4).tolil()
    A[5, :] = 0.0
    A[:, 5] = 0.0  # a node with no stiffness at all
    with pytest.raises(RuntimeError):
        spd_factor(A.tocsr())
