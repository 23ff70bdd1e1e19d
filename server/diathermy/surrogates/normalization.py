"""Input normalisation and output scaling of the CNN, stored as buffers so checkpoints carry them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

P_ATM_PA = 101325.0


@dataclass(frozen=True)
class FieldScales:
    """Scales that make the CNN's inputs and outputs O(1).

    p0_pa: reference pressure subtracted from the absolute pore pressure, Pa;
    pressure_scale_pa: divisor of p - p0, Pa; level_set_scale_m: divisor of phi, m;
    displacement_scale_m: the network's output is multiplied by it, m.
    """

    p0_pa: float = P_ATM_PA
    pressure_scale_pa: float = 1.0e4
    level_set_scale_m: float = 1.0e-2
    displacement_scale_m: float = 1.0e-4

    def __post_init__(self) -> None:
        for name in ("pressure_scale_pa", "level_set_scale_m", "displacement_scale_m"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0.0:
                raise ValueError(f"{name} must be a positive finite number, got {value}")


def fit_scales(
    pressure_pa: np.ndarray,
    level_set_m: np.ndarray,
    displacement_m: np.ndarray,
    *,
    p0_pa: float = P_ATM_PA,
) -> FieldScales:
    """Scales from training samples: RMS of p - p0, of phi and of u (floored so none is zero).

    pressure_pa, level_set_m: (S, nz, ny, nx); displacement_m: (S, nz, ny, nx, 3).
    """

    def rms(a: np.ndarray, floor: float) -> float:
        value = float(np.sqrt(np.mean(np.square(a, dtype=np.float64))))
        return value if np.isfinite(value) and value > floor else floor

    return FieldScales(
        p0_pa=p0_pa,
        pressure_scale_pa=rms(np.asarray(pressure_pa, np.float64) - p0_pa, 1.0),
        level_set_scale_m=rms(level_set_m, 1e-6),
        displacement_scale_m=rms(displacement_m, 1e-12),
    )


class FieldNormalizer(nn.Module):
    """Maps physical (p Pa, phi m) to network inputs and network outputs to u in m.

    Buffers: ``p0_pa``, ``pressure_scale_pa``, ``level_set_scale_m``, ``displacement_scale_m``
    (0-d float32 tensors), saved in the state dict.
    """

    p0_pa: torch.Tensor
    pressure_scale_pa: torch.Tensor
    level_set_scale_m: torch.Tensor
    displacement_scale_m: torch.Tensor

    def __init__(self, scales: FieldScales) -> None:
        super().__init__()
        for name, value in vars(scales).items():
            self.register_buffer(name, torch.tensor(float(value), dtype=torch.float32))

    def scales(self) -> FieldScales:
        """The scales as plain floats."""
        names = ("p0_pa", "pressure_scale_pa", "level_set_scale_m", "displacement_scale_m")
        return FieldScales(**{n: float(getattr(self, n)) for n in names})

    def encode_inputs(self, pressure_pa: torch.Tensor, level_set_m: torch.Tensor) -> torch.Tensor:
        """(N, D, H, W) pressure and level set -> (N, 2, D, H, W) normalised inputs."""
        p = (pressure_pa - self.p0_pa) / self.pressure_scale_pa
        phi = level_set_m / self.level_set_scale_m
        return torch.stack([p, phi], dim=1)

    def normalise_inputs(self, x: torch.Tensor) -> torch.Tensor:
        """(N, 2, D, H, W) physical (p Pa, phi m) -> normalised, same shape."""
        return self.encode_inputs(x[:, 0], x[:, 1])

    def encode_displacement(self, u_m: torch.Tensor) -> torch.Tensor:
        """(N, 3, D, H, W) displacement in m -> network units."""
        return u_m / self.displacement_scale_m

    def decode_displacement(self, y: torch.Tensor) -> torch.Tensor:
        """(N, 3, D, H, W) network output -> displacement in m."""
        return y * self.displacement_scale_m
