"""The shipped CNN as a mechanics predictor (``physics.predictors.DisplacementPredictor``): the
network's displacement for the incremental FEM backend's 'auto' choice, with no FEM of its own.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from diathermy.errors import CheckpointError
from diathermy.mesh import TetMesh
from diathermy.physics.mechanics import clamped_bottom
from diathermy.surrogates.checkpoint import grid_mismatch, load_checkpoint
from diathermy.surrogates.inference import default_device, predict


class CNNPredictor:
    """u (n_nodes, 3) m from nodal p (Pa) and phi (m) by a checkpoint of ``diathermy train``;
    the clamped bottom is held at 0. The checkpoint's grid and spacing must be the mesh's."""

    name = "cnn"

    def __init__(
        self,
        mesh: TetMesh,
        model_path: str | os.PathLike[str],
        *,
        device: str | torch.device | None = None,
    ) -> None:
        self.model_path = Path(model_path)
        dev = torch.device(device) if device is not None else default_device()
        grid = mesh.grid
        ckpt = load_checkpoint(self.model_path, expected_grid=grid.shape, map_location=dev)
        mismatch = grid_mismatch(ckpt, grid, str(self.model_path))
        if mismatch is not None:
            raise CheckpointError(mismatch)
        self.model = ckpt.model.eval().to(dev)
        self.shape = grid.shape
        self._fixed = clamped_bottom(mesh).mask(3 * mesh.n_nodes).reshape(-1, 3)
        self.n_predictions = 0

    def predict(
        self, pressure_pa: np.ndarray, level_set_m: np.ndarray, u_prev: np.ndarray | None = None
    ) -> np.ndarray:
        """The network's u (n_nodes, 3) m; ``u_prev`` is not used by this model."""
        del u_prev
        p = np.reshape(pressure_pa, self.shape)
        phi = np.reshape(level_set_m, self.shape)
        u = predict(self.model, p, phi).reshape(-1, 3).astype(np.float64)
        u[self._fixed] = 0.0
        self.n_predictions += 1
        return u
