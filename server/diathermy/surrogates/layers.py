"""Building blocks of the 3D CNN: convolution + activation, and pooled multi-scale branches.

Tensors are (N, C, D, H, W) = (N, C, nz, ny, nx), the node order of the grid.
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

# PyTorch sends a batch-1 conv3d to oneDNN only when N*C*D*H > 20480 and otherwise to a generic
# path 10-25x slower (benchmarks/results/cnn.md); inference calls oneDNN directly instead.
_ONEDNN_THRESHOLD = 20480


def _use_onednn_directly(x: torch.Tensor, weight: torch.Tensor) -> bool:
    return (
        x.device.type == "cpu"
        and x.dtype == torch.float32
        and weight.dtype == torch.float32
        and x.shape[0] * x.shape[1] * x.shape[2] * x.shape[3] <= _ONEDNN_THRESHOLD
        and not (torch.is_grad_enabled() and (x.requires_grad or weight.requires_grad))
        and not torch.is_autocast_enabled("cpu")
        and torch.backends.mkldnn.is_available()
    )


def conv3d_same(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None) -> torch.Tensor:
    """Stride-1 'same' Conv3d (odd kernel): (N, C_in, D, H, W) -> (N, C_out, D, H, W)."""
    pad = weight.shape[-1] // 2
    if _use_onednn_directly(x, weight):
        return torch.mkldnn_convolution(x, weight, bias, (pad,) * 3, (1, 1, 1), (1, 1, 1), 1)
    return F.conv3d(x, weight, bias, padding=pad)


class ConvAct(nn.Module):
    """Conv3d with 'same' padding followed by a leaky ReLU: (N, C_in, D, H, W) -> (N, C_out, D, H, W)."""

    def __init__(
        self, in_channels: int, out_channels: int, kernel_size: int, negative_slope: float
    ) -> None:
        super().__init__()
        if kernel_size not in (1, 3):
            raise ValueError(f"kernel_size must be 1 or 3, got {kernel_size}")
        self.conv = nn.Conv3d(in_channels, out_channels, kernel_size, padding=kernel_size // 2)
        self.negative_slope = negative_slope

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.leaky_relu(conv3d_same(x, self.conv.weight, self.conv.bias), self.negative_slope)


class PooledBranch(nn.Module):
    """Average-pool by ``factor``, convolve, upsample trilinearly back to the input's exact size.

    (N, C, D, H, W) -> (N, C, D, H, W) for any D, H, W (odd sizes included: pooling uses
    ``ceil_mode`` so no node is dropped, and the upsampling targets the input size itself).
    """

    def __init__(self, channels: int, factor: int, negative_slope: float) -> None:
        super().__init__()
        self.factor = factor
        self.block = ConvAct(channels, channels, 3, negative_slope)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        # grids thinner than the factor pool over what they have (a 3-node axis pools by 3)
        k = tuple(min(self.factor, n) for n in x.shape[-3:])
        pooled = F.avg_pool3d(x, k, k, ceil_mode=True, count_include_pad=False)
        y = self.block(pooled)
        return F.interpolate(y, size=x.shape[-3:], mode="trilinear", align_corners=False)
