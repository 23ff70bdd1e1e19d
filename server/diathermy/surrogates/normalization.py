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

    per_sample_amplitude: the mechanics is linear in p - p0 for a given topology, so the network
    may see the overpressure's shape only: p - p0 is divided by each sample's own amplitude
    a = max |p - p0| (Pa) and the output multiplied by a / pressure_scale_pa. The prediction is
    then exactly proportional to the overpressure (zero at p = p0), whatever the amplitude, and
    ``displacement_scale_m`` is the displacement at an amplitude of ``pressure_scale_pa``.
    """

    p0_pa: float = P_ATM_PA
    pressure_scale_pa: float = 1.0e4
    level_set_scale_m: float = 1.0e-2
    displacement_scale_m: float = 1.0e-4
    per_sample_amplitude: bool = False

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
    per_sample_amplitude: bool = False,
) -> FieldScales:
    """Scales from training samples: RMS of p - p0, of phi and of u (floored so none is zero).

    pressure_pa, level_set_m: (S, nz, ny, nx); displacement_m: (S, nz, ny, nx, 3). With
    ``per_sample_amplitude`` the pressure scale is the RMS of the samples' amplitudes
    max |p - p0| and the displacement scale the RMS of u rescaled to that amplitude (samples at
    p = p0 left out).
    """

    def rms(a: np.ndarray, floor: float) -> float:
        value = float(np.sqrt(np.mean(np.square(a, dtype=np.float64)))) if a.size else 0.0
        return value if np.isfinite(value) and value > floor else floor

    dp = np.asarray(pressure_pa, np.float64) - p0_pa
    if not per_sample_amplitude:
        return FieldScales(
            p0_pa=p0_pa,
            pressure_scale_pa=rms(dp, 1.0),
            level_set_scale_m=rms(level_set_m, 1e-6),
            displacement_scale_m=rms(displacement_m, 1e-12),
        )
    amp = np.abs(dp).reshape(dp.shape[0], -1).max(axis=1) if dp.size else np.zeros(0)
    live = amp > 0
    p_scale = rms(amp[live], 1.0)
    u = np.asarray(displacement_m, np.float64)[live]
    u_at_scale = u * (p_scale / amp[live]).reshape(-1, *([1] * (u.ndim - 1)))
    return FieldScales(
        p0_pa=p0_pa,
        pressure_scale_pa=p_scale,
        level_set_scale_m=rms(level_set_m, 1e-6),
        displacement_scale_m=rms(u_at_scale, 1e-12),
        per_sample_amplitude=True,
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
        self.per_sample_amplitude = bool(scales.per_sample_amplitude)  # a constructor argument
        for name in _BUFFERS:
            self.register_buffer(
                name, torch.tensor(float(getattr(scales, name)), dtype=torch.float32)
            )

    def scales(self) -> FieldScales:
        """The scales as plain floats."""
        values = {n: float(getattr(self, n)) for n in _BUFFERS}
        return FieldScales(**values, per_sample_amplitude=self.per_sample_amplitude)

    def max_overpressure(self, pressure_pa: torch.Tensor) -> torch.Tensor:
        """(N, D, H, W) pressure Pa -> (N,) each sample's max |p - p0|, Pa."""
        return (pressure_pa - self.p0_pa).abs().flatten(1).amax(dim=1)

    def amplitude(self, pressure_pa: torch.Tensor) -> torch.Tensor:
        """(N, D, H, W) pressure Pa -> (N, 1, 1, 1) divisor of p - p0, Pa.

        ``pressure_scale_pa`` for every sample, or each sample's max |p - p0| with
        ``per_sample_amplitude`` (``pressure_scale_pa`` where that is 0, whose output is then 0).
        """
        n = pressure_pa.shape[0]
        if not self.per_sample_amplitude:
            return self.pressure_scale_pa.expand(n, 1, 1, 1)
        amp = self.max_overpressure(pressure_pa).view(n, 1, 1, 1)
        return torch.where(amp > 0, amp, self.pressure_scale_pa)

    def output_gain(self, pressure_pa: torch.Tensor) -> torch.Tensor:
        """(N, D, H, W) pressure Pa -> (N, 1, 1, 1, 1) metres per network output unit."""
        gain = self.displacement_scale_m.expand(pressure_pa.shape[0], 1, 1, 1, 1)
        if not self.per_sample_amplitude:
            return gain
        amp = self.max_overpressure(pressure_pa)
        return gain * (amp / self.pressure_scale_pa).view(-1, 1, 1, 1, 1)

    def encode_inputs(self, pressure_pa: torch.Tensor, level_set_m: torch.Tensor) -> torch.Tensor:
        """(N, D, H, W) pressure and level set -> (N, 2, D, H, W) normalised inputs."""
        p = (pressure_pa - self.p0_pa) / self.amplitude(pressure_pa)
        phi = level_set_m / self.level_set_scale_m
        return torch.stack([p, phi], dim=1)

    def encode_displacement(self, u_m: torch.Tensor, pressure_pa: torch.Tensor) -> torch.Tensor:
        """(N, 3, D, H, W) displacement in m under (N, D, H, W) pressure Pa -> network units.

        Samples at p = p0 under ``per_sample_amplitude`` (gain 0) map to 0.
        """
        gain = self.output_gain(pressure_pa)
        return torch.where(gain > 0, u_m / torch.where(gain > 0, gain, 1.0), 0.0)

    def decode_displacement(self, y: torch.Tensor, pressure_pa: torch.Tensor) -> torch.Tensor:
        """(N, 3, D, H, W) network output under (N, D, H, W) pressure Pa -> displacement in m."""
        return y * self.output_gain(pressure_pa)


_BUFFERS = ("p0_pa", "pressure_scale_pa", "level_set_scale_m", "displacement_scale_m")
