"""The online-enrichment indicators: the estimated strain-energy error and the residual."""

from __future__ import annotations

import numpy as np
import pytest

from diathermy.physics.mechanics import MechanicsSolver
from diathermy.physics.strain_energy import relative_strain_energy_error, strain_energy_density
from diathermy.surrogates.pgd.backend import PGDBackend
from diathermy.surrogates.pgd.model import PGDModel
from diathermy.surrogates.pgd.online import (
    enrichment_indicator,
    equilibrium_residual,
    evaluate,
    reduce_state,
    strain_energy_indicator,
)
from tests.surrogates.pgd.conftest import H
from tests.surrogates.pgd.test_model import P0, TISSUE, _fem_case

ON = ((0.075, 0.0375), 1.2 * H, 1.6 * H)  # a training point of the tiny model
OFF = ((0.09, 0.045), 0.9 * H, 1.0 * H)  # between its positions, radii and craters


def _answer(model: PGDModel, point, n_modes: int | None):
    """FEM solver, pressure, the PGD answer (n_nodes, 3) m and its true W error."""
    position, radius, crater = point
    grid, mesh, geom, phi, removed, p, E, W = _fem_case(position, radius, crater)
    solver = MechanicsSolver(mesh, E, TISSUE.poisson_ratio, healthy=~removed, rtol=1e-10)
    st = reduce_state(
        model,
        mesh,
        grid,
        geom.volumes,
        pressure_pa=p,
        level_set_m=phi,
        healthy=~removed,
        position_m=position,
    )
    u = evaluate(model, st, n_modes)
    true = relative_strain_energy_error(
        strain_energy_density(geom.grads, mesh.tets, u, E, TISSUE.poisson_ratio), W
    )
    return solver, p, u, true


def test_energy_indicator_vanishes_where_the_modes_are_exact(tiny_model: PGDModel) -> None:
    solver, p, u, true = _answer(tiny_model, ON, None)
    ind = strain_energy_indicator(solver, u, p, P0, 10)
    assert true < 1e-3  # the full tiny model reproduces its training snapshot
    assert ind.value < 1e-3 and ind.value == pytest.approx(true, rel=0.1)
    assert ind.iterations == 10


@pytest.mark.parametrize(("point", "n_modes"), [(ON, 1), (OFF, None)])
def test_energy_indicator_is_large_where_the_modes_cannot_represent_the_state(
    tiny_model: PGDModel, point, n_modes: int | None
) -> None:
    solver, p, u, true = _answer(tiny_model, point, n_modes)
    ind = strain_energy_indicator(solver, u, p, P0, 5)
    assert true > 0.3
    assert ind.value > 0.3 and ind.value == pytest.approx(true, rel=0.2)
    # the CG-continued answer it computed on the way is closer to equilibrium than u
    assert equilibrium_residual(solver, ind.u, p, P0) < equilibrium_residual(solver, u, p, P0)


def test_energy_indicator_tends_to_the_true_error(tiny_model: PGDModel) -> None:
    solver, p, u, true = _answer(tiny_model, OFF, 3)
    ind = strain_energy_indicator(solver, u, p, P0, 500)
    assert ind.value == pytest.approx(true, rel=1e-4)


def test_residual_criterion_stays_selectable(tiny_model: PGDModel) -> None:
    solver, p, u, _ = _answer(tiny_model, OFF, None)
    ind = enrichment_indicator("residual", solver, u, p, P0)
    assert ind.value == equilibrium_residual(solver, u, p, P0) and ind.value > 0.1
    assert ind.iterations == 0 and np.array_equal(ind.u, u)
    with pytest.raises(ValueError, match="energy' or 'residual"):
        enrichment_indicator("norm", solver, u, p, P0)  # type: ignore[arg-type]


def test_backend_enriches_by_the_energy_indicator_by_default(tiny_model: PGDModel) -> None:
    position, radius, crater = OFF
    grid, mesh, geom, phi, removed, p, E, _ = _fem_case(position, radius, crater)
    backend = PGDBackend(tiny_model, mesh, grid, enrich_tol=0.1, position_fn=lambda: position)
    assert backend.enrich_criterion == "energy"
    kw = dict(pressure_pa=p, level_set_m=phi, youngs_modulus_pa=E, healthy=~removed)
    out = backend.solve(**kw, warm_start=None)
    assert out.extra["enriched"] and out.extra["indicator"] > 0.3 and out.residual < 1e-5
    again = backend.solve(**kw, warm_start=None)  # the new online mode represents the state
    assert not again.extra["enriched"] and again.extra["indicator"] < 1e-3
    with pytest.raises(ValueError, match="enrich_criterion"):
        PGDBackend(tiny_model, mesh, grid, enrich_criterion="norm")  # type: ignore[arg-type]
