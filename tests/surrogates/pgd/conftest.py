"""A tiny PGD model on a 9x9x17 grid, built once per session (16 FEM snapshots, 40 modes)."""

from __future__ import annotations

from pathlib import Path

import pytest

from diathermy.physics.materials import Tissue
from diathermy.surrogates.pgd.model import PGDModel, save_model
from diathermy.surrogates.pgd.offline import TrainingManifold, build_model

GRID = (9, 9, 17)
BLOCK = (0.2, 0.1, 0.1)
H = BLOCK[0] / (GRID[2] - 1)  # 12.5 mm


def tiny_manifold(n_modes: int = 40) -> TrainingManifold:
    """2 x 2 positions x 2 radii x 2 topologies (intact, a crater at the centre)."""
    return TrainingManifold(
        electrode_x_m=(0.075, 0.1),
        electrode_y_m=(0.0375, 0.05),
        radius_m=(0.6 * H, 1.2 * H),
        craters=((0.1, 0.05, 0.0), (0.1, 0.05, 1.6 * H)),
        n_modes=n_modes,
        tol=1e-12,
        fem_rtol=1e-9,
        max_fixed_point=200,
        fixed_point_tol=1e-10,
    )


@pytest.fixture(scope="session")
def tiny_model() -> PGDModel:
    return build_model(tiny_manifold(), GRID, BLOCK, Tissue())


@pytest.fixture(scope="session")
def tiny_model_file(tiny_model: PGDModel, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return save_model(tiny_model, tmp_path_factory.mktemp("pgd") / "tiny.npz")
