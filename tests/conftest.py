"""Shared fixtures: small meshes that every physics test can afford."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

from diathermy.mesh import Grid, TetMesh, build_tet_mesh

# Shared 2-core CI machines are noisy: judge examples by outcome, never by wall time.
settings.register_profile(
    "diathermy", deadline=None, suppress_health_check=[HealthCheck.too_slow], max_examples=60
)
settings.load_profile("diathermy")


@pytest.fixture(scope="session")
def small_mesh() -> TetMesh:
    """A 5x6x7-node mesh with unequal spacing in each direction."""
    return build_tet_mesh(Grid((5, 6, 7), size_m=(0.03, 0.02, 0.01), origin_m=(0.1, -0.2, 0.0)))


@pytest.fixture()
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)
