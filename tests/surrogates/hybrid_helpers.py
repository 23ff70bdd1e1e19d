"""A small FEM sample (pressure dome under a crater) and a CNN overfit to it, for hybrid tests."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from diathermy.mesh import Grid, TetMesh, build_tet_mesh
from diathermy.physics.levelset import initial_level_set
from diathermy.physics.materials import Tissue
from diathermy.physics.mechanics import MechanicsSolver
from diathermy.physics.topology import removed_fraction, removed_tets
from diathermy.surrogates.checkpoint import save_checkpoint
from diathermy.surrogates.cnn import CNNConfig, DisplacementCNN
from diathermy.surrogates.normalization import fit_scales

GRID = (9, 9, 17)
BLOCK_M = (0.02, 0.01, 0.01)  # tests/engine/scenes.py: tiny_scene's block


@dataclass(frozen=True)
class FemSample:
    """A mesh, the engine's inputs of one mechanics step and the FEM answer."""

    mesh: TetMesh
    pressure_pa: np.ndarray  # (n_nodes,)
    level_set_m: np.ndarray  # (n_nodes,)
    youngs_modulus_pa: np.ndarray  # (n_tets,)
    healthy: np.ndarray  # (n_tets,)
    u: np.ndarray  # (n_nodes, 3) FEM, rtol 1e-10


def fem_sample(amplitude_pa: float = 4.0e5, crater_m: float = 2.5e-3) -> FemSample:
    """A Gaussian pore-pressure dome under a crater at the top centre, solved by FEM."""
    tissue = Tissue()
    grid = Grid(GRID, size_m=BLOCK_M)
    mesh = build_tet_mesh(grid)
    x, y, z = mesh.points.T
    cx, cy, top = BLOCK_M[0] / 2, BLOCK_M[1] / 2, BLOCK_M[2]
    r2 = (x - cx) ** 2 + (y - cy) ** 2
    p = tissue.p_atm_pa + amplitude_pa * np.exp(-(r2 + (z - top) ** 2) / (2 * 0.002**2))
    phi = initial_level_set(grid).ravel() - crater_m * np.exp(-r2 / (2 * 0.0015**2))
    removed = removed_tets(removed_fraction(phi, mesh.tets))
    E = np.where(removed, tissue.ersatz_stiffness_ratio, 1.0) * tissue.youngs_modulus_pa
    healthy = ~removed
    solver = MechanicsSolver(mesh, E, tissue.poisson_ratio, healthy=healthy, rtol=1e-10)
    u = solver.solve(p, tissue.p_atm_pa).u
    return FemSample(mesh, p, phi, E, healthy, u)


def overfit_model(sample: FemSample, path: Path, *, iterations: int = 100, seed: int = 0) -> Path:
    """Fit a small CNN to the single sample (L-BFGS on the L2 error of u); save a checkpoint."""
    torch.manual_seed(seed)
    g = sample.mesh.grid
    p = sample.pressure_pa.reshape(g.shape)[None].astype(np.float32)
    phi = sample.level_set_m.reshape(g.shape)[None].astype(np.float32)
    u = sample.u.reshape(*g.shape, 3)[None].astype(np.float32)
    model = DisplacementCNN(CNNConfig(width=8, depth=2), fit_scales(p, phi, u))
    x = model.normalizer.encode_inputs(torch.from_numpy(p), torch.from_numpy(phi))
    target = model.normalizer.encode_displacement(
        torch.from_numpy(u).permute(0, 4, 1, 2, 3), torch.from_numpy(p)
    )
    opt = torch.optim.LBFGS(
        model.parameters(), lr=1.0, max_iter=iterations, history_size=20,
        line_search_fn="strong_wolfe", tolerance_grad=0.0, tolerance_change=0.0,
    )  # fmt: skip

    def closure() -> torch.Tensor:
        opt.zero_grad()
        loss = torch.mean((model(x) - target) ** 2)
        loss.backward()
        return loss

    opt.step(closure)
    save_checkpoint(path, model.eval(), grid_shape=g.shape, spacing_m=g.spacing_m)
    return path


def untrained_model(path: Path, grid: tuple[int, int, int] = GRID, seed: int = 1) -> Path:
    """A freshly initialised width-4 CNN for ``grid`` on BLOCK_M (a poor but valid model)."""
    torch.manual_seed(seed)
    g = Grid(grid, size_m=BLOCK_M)
    model = DisplacementCNN(CNNConfig(width=4, depth=1))
    save_checkpoint(path, model.eval(), grid_shape=g.shape, spacing_m=g.spacing_m)
    return path
