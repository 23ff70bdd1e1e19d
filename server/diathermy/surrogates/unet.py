"""A 3D U-Net body: encoder levels that halve the grid, a decoder with skip connections.

The elastic response to a local load is global, while the paper's network sees a limited
neighbourhood (a 3^5 trunk and branches pooled by 2 and 4). Each level of this body halves every
axis (ceil, so odd node counts lose no node), so ``levels`` = 4 spans 16 cells per axis at the
bottom and sees the default scene's 35x32x48 block whole; the skips carry the fine detail of the
crater wall back up. Tensors are (N, C, D, H, W) = (N, C, nz, ny, nx); any D, H, W >= 1 works.
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

from diathermy.surrogates.layers import ConvAct

ARCHS = ("pooled", "unet")
"""The networks' bodies: the paper's pooled layout, or this U-Net."""


def check_arch(arch: str, levels: int) -> None:
    """ValueError unless ``arch`` is one of ``ARCHS`` and ``levels`` lies in 1..6."""
    if arch not in ARCHS:
        raise ValueError(f"arch must be one of {ARCHS}, got {arch!r}")
    if not 1 <= levels <= 6:
        raise ValueError(f"levels must lie in 1..6, got {levels}")


class ConvBlock(nn.Module):
    """Two 3^3 convolutions with leaky ReLUs: (N, C_in, D, H, W) -> (N, C_out, D, H, W)."""

    def __init__(self, in_channels: int, out_channels: int, negative_slope: float) -> None:
        super().__init__()
        self.a = ConvAct(in_channels, out_channels, 3, negative_slope)
        self.b = ConvAct(out_channels, out_channels, 3, negative_slope)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.b(self.a(x))


class UNet3D(nn.Module):
    """(N, in_channels, D, H, W) -> (N, width, D, H, W) features (the caller adds its head).

    Level k has ``width * 2**k`` channels (capped at 8x ``width``); pooling is a 2^3 average with
    ``ceil_mode``, upsampling trilinear to the skip's exact size, then concatenation and a
    ``ConvBlock``. The coarse levels hold most weights: at width 12 and 4 levels about 2.1 M,
    against 25 k in the paper's layout of that width (a checkpoint of ~8 MB).
    """

    def __init__(self, in_channels: int, width: int, levels: int, negative_slope: float) -> None:
        super().__init__()
        if width < 1 or levels < 1:
            raise ValueError(f"width and levels must be >= 1, got {width}, {levels}")
        chans = [width * min(2**k, 8) for k in range(levels + 1)]
        self.down = nn.ModuleList(
            ConvBlock(in_channels if k == 0 else chans[k - 1], chans[k], negative_slope)
            for k in range(levels)
        )
        self.bottom = ConvBlock(chans[levels - 1], chans[levels], negative_slope)
        self.up = nn.ModuleList(
            ConvBlock(chans[k + 1] + chans[k], chans[k], negative_slope)
            for k in reversed(range(levels))
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        skips = []
        for block in self.down:
            x = block(x)
            skips.append(x)
            # an axis of one node has nothing to pool: it keeps its size
            k = tuple(min(2, n) for n in x.shape[-3:])
            x = F.avg_pool3d(x, k, k, ceil_mode=True, count_include_pad=False)
        x = self.bottom(x)
        for block, skip in zip(self.up, reversed(skips), strict=True):
            x = F.interpolate(x, size=skip.shape[-3:], mode="trilinear", align_corners=False)
            x = block(torch.cat([x, skip], dim=1))
        return x
