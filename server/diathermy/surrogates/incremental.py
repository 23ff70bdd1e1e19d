"""The incremental mechanics network: the last step's answer and what changed -> this step's change.

For a fixed topology the mechanics is linear in the overpressure, u = A(phi) (p - p0), so between
two steps

    u_new - u_prev = A(phi_new) (p_new - p_prev) + (A(phi_new) - A(phi_prev)) (p_prev - p0):

the pressure change acts through the new topology, and a cut releases the stress that the old
overpressure held where tets were removed. The network sees the inputs of both terms and predicts
the change; its output layer starts at zero, so an untrained model is persistence, and training
learns what persistence misses (issue #22, item 3).

Inputs (N, 7, D, H, W) = (nz, ny, nx) node grids: (p_new - p_prev) / a, (p_prev - p0) / a,
u_prev / (a g) (3 components), phi_new / phi_scale and the tissue mask phi_new > 0, with one
amplitude per sample a = max(max |p_new - p0|, max |p_prev - p0|) in Pa and a displacement gain g
in m/Pa fitted to the data. Output (N, 3, D, H, W): (u_new - u_prev) / (a g_change), with a gain
of its own for the change (a step's change is a few per cent of u, and an O(1) target trains
better). Scaling every
overpressure and u_prev by c > 0 scales the predicted change by c, as the mechanics does.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from diathermy.surrogates.layers import ConvAct, PooledBranch, conv3d_same
from diathermy.surrogates.unet import UNet3D, check_arch

IN_CHANNELS = 7
OUT_CHANNELS = 3


@dataclass(frozen=True)
class IncrementalConfig:
    """Constructor arguments of :class:`IncrementalCNN` (stored verbatim in checkpoints).

    ``arch``: "pooled", the paper's layout (a full-resolution trunk of ``depth`` convolutions
    and branches pooled by each of ``pools``: 2 and 4 in the paper, 8 widens the receptive field
    toward the block's size), or "unet", a U-Net of ``levels`` levels
    (``diathermy.surrogates.unet``; ``depth`` and ``pools`` are then unused).
    """

    width: int = 16
    depth: int = 5
    pools: tuple[int, ...] = (2, 4, 8)
    negative_slope: float = 0.01
    p0_pa: float = 101325.0
    level_set_scale_m: float = 1.0e-3
    gain_m_per_pa: float = 1.0e-9
    change_gain_m_per_pa: float = 1.0e-10
    arch: str = "pooled"
    levels: int = 4

    def __post_init__(self) -> None:
        if self.width < 1 or self.depth < 1:
            raise ValueError(f"width and depth must be >= 1, got {self.width}, {self.depth}")
        check_arch(self.arch, self.levels)
        if any(int(k) < 2 for k in self.pools):
            raise ValueError(f"pools must be factors >= 2, got {self.pools}")
        for name in ("level_set_scale_m", "gain_m_per_pa", "change_gain_m_per_pa"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0.0:
                raise ValueError(f"{name} must be a positive finite number, got {value}")


class IncrementalCNN(nn.Module):
    """Multi-scale 3D CNN over (N, 7, D, H, W) normalised inputs -> (N, 3, D, H, W) change of u.

    Use :meth:`predict_displacement` for physical units (Pa, m in; m out).
    """

    def __init__(self, config: IncrementalConfig | None = None) -> None:
        super().__init__()
        self.config = config or IncrementalConfig()
        c = self.config
        w, slope = c.width, c.negative_slope
        if c.arch == "unet":
            self.body = UNet3D(IN_CHANNELS, w, c.levels, slope)
        else:
            self.stem = ConvAct(IN_CHANNELS, w, 3, slope)
            self.trunk = nn.Sequential(*(ConvAct(w, w, 3, slope) for _ in range(c.depth - 1)))
            self.branches = nn.ModuleList(PooledBranch(w, int(k), slope) for k in c.pools)
            self.head = ConvAct(w, w, 1, slope)
        self.out = nn.Conv3d(w, OUT_CHANNELS, 1)
        nn.init.zeros_(self.out.weight)  # an untrained model predicts no change: persistence
        if self.out.bias is not None:
            nn.init.zeros_(self.out.bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(N, 7, D, H, W) normalised inputs -> (N, 3, D, H, W) normalised change of u."""
        if self.config.arch == "unet":
            return conv3d_same(self.body(x), self.out.weight, self.out.bias)
        h = self.stem(x)
        y = self.trunk(h)
        for branch in self.branches:
            y = y + branch(h)
        return conv3d_same(self.head(y), self.out.weight, self.out.bias)

    def amplitude(self, p_new: torch.Tensor, p_prev: torch.Tensor) -> torch.Tensor:
        """(N, D, H, W) pressures Pa -> (N,) a = max |p - p0| over both steps, Pa (0: none)."""
        p0 = self.config.p0_pa
        return torch.maximum(
            (p_new - p0).abs().flatten(1).amax(1), (p_prev - p0).abs().flatten(1).amax(1)
        )

    def encode(
        self,
        p_new: torch.Tensor,
        p_prev: torch.Tensor,
        u_prev: torch.Tensor,
        phi_new: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Physical fields -> ((N, 7, D, H, W) inputs, (N, 1, 1, 1, 1) metres per output unit,
        0 for a sample with no overpressure at either step: nothing loads it, nothing changes).

        p_new, p_prev: (N, D, H, W) Pa; u_prev: (N, 3, D, H, W) m; phi_new: (N, D, H, W) m.
        """
        c = self.config
        a = self.amplitude(p_new, p_prev).view(-1, 1, 1, 1)
        safe = torch.where(a > 0, a, torch.ones_like(a))  # no overpressure: no change (gain 0)
        x = torch.cat(
            [
                ((p_new - p_prev) / safe).unsqueeze(1),
                ((p_prev - c.p0_pa) / safe).unsqueeze(1),
                u_prev / (safe * c.gain_m_per_pa).unsqueeze(1),
                (phi_new / c.level_set_scale_m).unsqueeze(1),
                (phi_new > 0).to(p_new.dtype).unsqueeze(1),
            ],
            dim=1,
        )
        return x, (a * c.change_gain_m_per_pa).unsqueeze(1)

    def predict_displacement(
        self,
        p_new: torch.Tensor,
        p_prev: torch.Tensor,
        u_prev: torch.Tensor,
        phi_new: torch.Tensor,
    ) -> torch.Tensor:
        """(N, 3, D, H, W) u_new in m: u_prev plus the predicted change (shapes as in encode)."""
        x, gain = self.encode(p_new, p_prev, u_prev, phi_new)
        return u_prev + self(x) * gain

    def constructor_args(self) -> dict[str, Any]:
        """Plain-dict constructor arguments for checkpoints."""
        return {"config": {**asdict(self.config), "pools": list(self.config.pools)}}

    @classmethod
    def from_constructor_args(cls, args: dict[str, Any]) -> IncrementalCNN:
        """Inverse of :meth:`constructor_args`."""
        cfg = dict(args["config"])
        cfg["pools"] = tuple(int(k) for k in cfg["pools"])
        return cls(IncrementalConfig(**cfg))


def _rms_per_pa(a: np.ndarray, u: np.ndarray) -> float:
    live = a > 0
    if not live.any():
        return 1.0e-9
    umax = np.abs(u[live]).reshape(int(live.sum()), -1).max(1)
    g = float(np.sqrt(np.mean((umax / a[live]) ** 2)))
    return g if np.isfinite(g) and g > 0 else 1.0e-9


def _amplitudes(p_new_pa: np.ndarray, p_prev_pa: np.ndarray, p0_pa: float) -> np.ndarray:
    return np.maximum(
        np.abs(p_new_pa - p0_pa).reshape(len(p_new_pa), -1).max(1),
        np.abs(p_prev_pa - p0_pa).reshape(len(p_prev_pa), -1).max(1),
    )


def fit_gain(
    p_new_pa: np.ndarray, p_prev_pa: np.ndarray, u_new_m: np.ndarray, p0_pa: float
) -> float:
    """Displacement per Pa of overpressure (m/Pa): RMS over samples of max |u| / a.

    p_new_pa, p_prev_pa: (S, D, H, W) Pa; u_new_m: (S, 3, D, H, W) m. Samples at p = p0 are
    left out; 1e-9 when none is left (as when every max |u| / a is 0)."""
    return _rms_per_pa(_amplitudes(p_new_pa, p_prev_pa, p0_pa), u_new_m)


def fit_change_gain(
    p_new_pa: np.ndarray,
    p_prev_pa: np.ndarray,
    u_new_m: np.ndarray,
    u_prev_m: np.ndarray,
    p0_pa: float,
) -> float:
    """Displacement change per Pa of overpressure (m/Pa): RMS of max |u_new - u_prev| / a
    (shapes as in :func:`fit_gain`)."""
    return _rms_per_pa(_amplitudes(p_new_pa, p_prev_pa, p0_pa), u_new_m - u_prev_m)
