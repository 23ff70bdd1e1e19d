"""The torch W on the Kuhn mesh equals the mechanics' numpy W, and the loss on it trains."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from diathermy.fem.geometry import structured_geometry
from diathermy.mesh import Grid, build_tet_mesh
from diathermy.physics.materials import Tissue
from diathermy.physics.strain_energy import relative_strain_energy_error, strain_energy_density
from diathermy.physics.strain_energy_error import tet_youngs_modulus
from diathermy.surrogates.losses import training_loss
from diathermy.surrogates.strain_energy import (
    GridStrainEnergy,
    relative_strain_energy_error_squared,
)
from diathermy.surrogates.train_config import TrainConfig
from diathermy.surrogates.training import train


def _fields(grid: Grid, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(*grid.shape, 3)) * 1e-4
    phi = rng.normal(size=grid.shape) * 1e-3 + 5e-4  # about a third of the tets removed
    return u, phi


def _torch(u: np.ndarray, phi: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
    return torch.tensor(u).permute(3, 0, 1, 2)[None].float(), torch.tensor(phi)[None].float()


@pytest.mark.parametrize("size_m", [(0.012, 0.010, 0.008), (0.010, 0.021, 0.006)])
def test_w_matches_the_mechanics_definition_per_tet(size_m: tuple[float, float, float]) -> None:
    grid = Grid((5, 6, 7), size_m=size_m)  # anisotropic cells in the second case
    mesh = build_tet_mesh(grid)
    geom = structured_geometry(mesh.points, mesh.tets, mesh.shape_id)
    tissue = Tissue()
    u, phi = _fields(grid, 0)
    E = tet_youngs_modulus(phi, mesh, tissue)
    assert 0.1 < np.mean(E < tissue.youngs_modulus_pa) < 0.9  # both kinds of tets are tested
    W_np = strain_energy_density(geom.grads, mesh.tets, u.reshape(-1, 3), E, tissue.poisson_ratio)
    module = GridStrainEnergy(grid.spacing_m, tissue.poisson_ratio, tissue.ersatz_stiffness_ratio)
    W = module(*_torch(u, phi)).permute(0, 2, 3, 4, 1).reshape(-1).double().numpy()
    W = W * tissue.youngs_modulus_pa  # the module's W is in units of E
    np.testing.assert_allclose(W, W_np, rtol=2e-5, atol=1e-6 * np.abs(W_np).max())


def test_relative_error_is_the_metric_squared() -> None:
    grid = Grid((4, 5, 6), size_m=(0.01, 0.01, 0.01))
    tissue = Tissue()
    module = GridStrainEnergy(grid.spacing_m, tissue.poisson_ratio, tissue.ersatz_stiffness_ratio)
    u, phi = _fields(grid, 1)
    u2 = u + np.random.default_rng(2).normal(size=u.shape) * 2e-5
    W_ref = module(*_torch(u, phi))
    W = module(*_torch(u2, phi))
    got = float(relative_strain_energy_error_squared(W, W_ref)[0])
    want = relative_strain_energy_error(W.double().numpy(), W_ref.double().numpy()) ** 2
    assert got == pytest.approx(want, rel=1e-4)
    zero = torch.zeros_like(W_ref)
    assert float(relative_strain_energy_error_squared(zero, zero)[0]) == 0.0


def test_energy_term_is_zero_at_the_target_and_has_gradients() -> None:
    grid = Grid((4, 5, 6), size_m=(0.01, 0.01, 0.01))
    module = GridStrainEnergy(grid.spacing_m, 0.4, 1e-6)
    u, phi = _torch(*_fields(grid, 3))
    pred = (u * 1.1).requires_grad_(True)
    loss = training_loss(pred, u, 0.0, 1.0, module, phi)
    loss.backward()
    assert pred.grad is not None and float(pred.grad.abs().max()) > 0
    exact = training_loss(u, u, 0.0, 1.0, module, phi)
    assert float(exact) == 0.0
    # W scales as u^2: a 10 % larger field has (1.21 - 1)^2 = 0.0441 squared relative W error
    only_energy = loss.detach() - training_loss(pred.detach(), u, 0.0)
    assert float(only_energy) == pytest.approx(0.21**2, rel=1e-4)
    with pytest.raises(ValueError, match="energy term"):
        training_loss(pred, u, 0.0, 1.0)


def test_training_on_the_energy_term_lowers_it(tiny_dataset: Path, tmp_path: Path) -> None:
    cfg = TrainConfig(width=6, depth=3, epochs=10, batch_size=4, lr=3e-3, patience=50, seed=7)
    result = train(tiny_dataset, tmp_path / "m.pt", replace(cfg, energy_weight=1.0), progress=False)
    val = [h["val_loss"] for h in result.history]
    assert val[-1] < 0.7 * val[0]
    with pytest.raises(Exception, match="energy_weight"):
        TrainConfig(energy_weight=-1.0)
