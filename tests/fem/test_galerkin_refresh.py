"""A kept hierarchy's coarse operators refreshed for a cut: they equal the Galerkin products
R A P of the new operator with the kept prolongators, depend on (build-time, current) operator
alone (a restored checkpoint repeats them bit for bit), and make the kept hierarchy precondition
the cut block in fewer CG iterations than the fine-level swap alone."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from diathermy.fem.galerkin_refresh import GalerkinRefresh
from diathermy.fem.solvers import KrylovSolver
from diathermy.mesh import Grid, build_tet_mesh
from diathermy.physics.mechanics import DEFAULT_AMG_OPTIONS, MechanicsSolver

E, NU, P0 = 0.27e6, 0.4, 101325.0


def _krylov(refresh: bool) -> KrylovSolver:
    return KrylovSolver(
        "elasticity",
        rtol=1e-8,
        amg_options={**DEFAULT_AMG_OPTIONS, "max_coarse": 16},
        stale_factor=1e6,
        refresh_coarse=refresh,
    )


def _cut(mesh, radius: float) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """(E, healthy) with a ball of the given radius (m) at the top face's centre cut out."""
    c = mesh.centroids()
    healthy = np.linalg.norm(c - [0.1, 0.05, 0.1], axis=1) > radius
    return np.where(healthy, E, 1e-6 * E), healthy


@pytest.fixture(scope="module")
def mesh():  # noqa: ANN201
    return build_tet_mesh(Grid((9, 9, 17)))


def _chain(mesh, refresh: bool, radii: tuple[float, ...]) -> list[MechanicsSolver]:  # noqa: ANN001
    """A solver per radius, each updating the last one's stiffness in place (the engine's
    chain), sharing one kept hierarchy built for the first."""
    k = _krylov(refresh)
    out: list[MechanicsSolver] = []
    for r in radii:
        E_r, healthy = _cut(mesh, r)
        base = out[-1] if out else None
        solver = MechanicsSolver(
            mesh,
            E_r,
            NU,
            healthy=healthy,
            assembler=base.assembler if base else None,
            krylov=k,
            base=base,
            consume_base=True,
        )
        assert base is None or solver.updated  # the blocks of the changed tets, in place
        out.append(solver)
        if base is None:
            k.build()
    return out


def _levels(k: KrylovSolver) -> list[sp.spmatrix]:
    return [lvl.A for lvl in k._ml.levels]  # noqa: SLF001


def test_refreshed_coarse_operators_are_the_galerkin_products(mesh):  # noqa: ANN001
    chain = _chain(mesh, True, (0.015, 0.025, 0.03))
    k = chain[-1].krylov
    assert k.kept_preconditioner is not None  # refreshes
    assert k.last_refresh is not None and k.last_refresh.applied
    assert k.last_refresh.changed_blocks > 0 and all(n > 0 for n in k.last_refresh.coarse_entries)
    levels = k._ml.levels  # noqa: SLF001
    assert len(levels) >= 3
    for lvl, coarse in zip(levels[:-1], levels[1:], strict=True):
        exact = (lvl.R @ lvl.A @ lvl.P).toarray()
        assert np.abs(coarse.A.toarray() - exact).max() <= 1e-12 * np.abs(exact).max()


def test_coarsest_solve_follows_the_refresh(mesh):  # noqa: ANN001
    """The coarsest direct solve (a Cholesky factor formed at its first use) is the refreshed
    operator's, not the one of the build it was first formed for."""
    first = _chain(mesh, True, (0.015,))[0]
    k = first.krylov
    _ = k.kept_preconditioner @ np.ones(k.A.shape[0])  # forms the build's factor
    E_r, healthy = _cut(mesh, 0.03)
    MechanicsSolver(
        mesh,
        E_r,
        NU,
        healthy=healthy,
        assembler=first.assembler,
        krylov=k,
        base=first,
        consume_base=True,
    )
    assert k.kept_preconditioner is not None and k.last_refresh is not None
    assert k.last_refresh.coarse_entries[-1] > 0
    Ac = k._ml.levels[-1].A  # noqa: SLF001
    b = Ac @ np.random.default_rng(1).normal(size=Ac.shape[0])
    x = k._ml.coarse_solver(Ac, b)  # noqa: SLF001
    exact_x = np.linalg.pinv(Ac.toarray()) @ b
    assert np.linalg.norm(x - exact_x) <= 1e-9 * np.linalg.norm(exact_x)


def test_refresh_depends_on_build_and_current_operator_alone(mesh):  # noqa: ANN001
    """Through the step-by-step chain with its change hints, or at once from the build-time
    operator with no hint (a restored checkpoint), the coarse levels agree bit for bit; going
    back to the build-time operator gives back the build-time coarse levels."""
    chain = _chain(mesh, True, (0.015, 0.02, 0.025, 0.03))
    k = chain[-1].krylov
    k.kept_preconditioner  # noqa: B018 (refreshes)
    stepped = [A.data.copy() for A in _levels(k)[1:]]
    first = _chain(mesh, True, (0.015,))[0]
    k2 = first.krylov
    built = [A.data.copy() for A in _levels(k2)[1:]]
    E_r, healthy = _cut(mesh, 0.03)
    fresh = MechanicsSolver(mesh, E_r, NU, healthy=healthy)
    k2.set_operator(fresh.K_scaled, scale=fresh.scale)  # no hint: every block a candidate
    k2.kept_preconditioner  # noqa: B018
    for a, b in zip(stepped, _levels(k2)[1:], strict=True):
        assert np.array_equal(a, b.data)
    v = np.random.default_rng(3).normal(size=k.A.shape[0])
    assert np.array_equal(k.kept_preconditioner @ v, k2.kept_preconditioner @ v)  # smoothers too
    k2.set_operator(first.K_scaled, scale=first.scale)
    k2.kept_preconditioner  # noqa: B018
    for a, b in zip(built, _levels(k2)[1:], strict=True):
        assert np.array_equal(a, b.data)


def test_refresh_saves_cg_iterations_on_the_cut_block(mesh):  # noqa: ANN001
    r = np.linalg.norm(mesh.points - [0.1, 0.05, 0.1], axis=1)
    p = P0 + 2e5 * np.exp(-((r / 0.03) ** 2))
    its = {}
    for refresh in (False, True):
        last = _chain(mesh, refresh, (0.015, 0.03))[-1]
        res = last.solve(p, P0)
        assert res.stats.stale and not res.stats.rebuilt
        its[refresh] = res.stats.iterations
        assert np.all(np.isfinite(res.u))
    assert its[True] < its[False]


def test_other_sparsity_leaves_the_build_time_coarse_levels(mesh):  # noqa: ANN001
    first = _chain(mesh, True, (0.015,))[0]
    ml = first.krylov._ml  # noqa: SLF001
    g = GalerkinRefresh(ml)
    built = [lvl.A.data.copy() for lvl in ml.levels[1:]]
    A = first.krylov.A.tocsr()  # same matrix, CSR: another block layout
    assert not g.refresh(A).applied
    for a, lvl in zip(built, ml.levels[1:], strict=True):
        assert np.array_equal(a, lvl.A.data)
