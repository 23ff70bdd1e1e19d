"""Inference: numpy fields in, numpy displacement out, on the model's device."""

from __future__ import annotations

import numpy as np
import torch

from diathermy.surrogates.cnn import DisplacementCNN


def default_device() -> torch.device:
    """The GPU when there is one, else the CPU."""
    return torch.device("cuda" if torch.cuda.is_available() else "cpu")


def predict(
    model: DisplacementCNN,
    pressure_pa: np.ndarray,
    level_set_m: np.ndarray,
    *,
    channels_last: bool = False,
) -> np.ndarray:
    """Absolute pressure (nz, ny, nx) Pa and level set (nz, ny, nx) m -> u (nz, ny, nx, 3) m.

    A leading batch axis (B, nz, ny, nx) -> (B, nz, ny, nx, 3) works too. ``channels_last``
    uses the channels_last_3d layout (the model should have been converted with
    ``model.to(memory_format=torch.channels_last_3d)``; see benchmarks/results/cnn.md).
    """
    p = np.asarray(pressure_pa, np.float32)
    phi = np.asarray(level_set_m, np.float32)
    if p.shape != phi.shape or p.ndim not in (3, 4):
        raise ValueError(f"pressure {p.shape} and level set {phi.shape} must share (nz, ny, nx)")
    single = p.ndim == 3
    device = next(model.parameters()).device
    with torch.inference_mode():
        pt = torch.from_numpy(p[None] if single else p).to(device)
        phit = torch.from_numpy(phi[None] if single else phi).to(device)
        x = model.normalizer.encode_inputs(pt, phit)
        if channels_last:
            x = x.contiguous(memory_format=torch.channels_last_3d)
        u = model.normalizer.decode_displacement(model(x), pt)
        out = u.permute(0, 2, 3, 4, 1).float().cpu().numpy()
    return np.ascontiguousarray(out[0] if single else out)
