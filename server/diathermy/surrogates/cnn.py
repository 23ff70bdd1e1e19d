"""The 3D CNN surrogate of the mechanics: (p - p0, phi) on the grid -> displacement u.

Architecture (DESIGN.md, "Surrogates -> CNN"): ``depth`` stages of Conv3d + leaky ReLU at full
resolution; the first stage's output also feeds two branches averaged by 2 and by 4, each
convolved and upsampled trilinearly to the exact grid size, summed with the full-resolution
trunk; a 1x1x1 convolution + leaky ReLU and a final 1x1x1 convolution give the three components.
``CNNConfig.arch`` "unet" swaps that body for a U-Net (``diathermy.surrogates.unet``) before the
final convolution.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import torch
from torch import nn

from diathermy.surrogates.layers import ConvAct, PooledBranch, conv3d_same
from diathermy.surrogates.normalization import FieldNormalizer, FieldScales
from diathermy.surrogates.unet import UNet3D, check_arch

IN_CHANNELS = 2  # (p - p0) / p_scale, phi / phi_scale
OUT_CHANNELS = 3  # u_x, u_y, u_z / u_scale


@dataclass(frozen=True)
class CNNConfig:
    """Constructor arguments of :class:`DisplacementCNN` (stored verbatim in checkpoints)."""

    width: int = 16
    depth: int = 5
    negative_slope: float = 0.01
    # a third input channel, the tissue mask H(phi): 1 at nodes with phi > 0, 0 in the cut. The
    # stiffness jumps there (healthy E vs the ersatz ratio); phi alone, a smooth distance, makes
    # the first layer learn a step from it.
    mask_input: bool = False
    # "pooled": the paper's layout (trunk of ``depth`` convolutions, branches pooled by 2 and 4);
    # "unet": a U-Net of ``levels`` levels (diathermy.surrogates.unet), which sees the whole block
    arch: str = "pooled"
    levels: int = 4

    def __post_init__(self) -> None:
        check_arch(self.arch, self.levels)
        if self.width < 1:
            raise ValueError(f"width must be >= 1, got {self.width}")
        if self.depth < 1:
            raise ValueError(f"depth must be >= 1, got {self.depth}")
        if not 0.0 <= self.negative_slope < 1.0:
            raise ValueError(f"negative_slope must lie in [0, 1), got {self.negative_slope}")


class DisplacementCNN(nn.Module):
    """Multi-scale 3D CNN; ``forward`` maps normalised (N, 2, D, H, W) to normalised (N, 3, D, H, W).

    With ``config.mask_input`` the forward pass appends the mask phi > 0 as a third channel itself,
    so every caller passes the same two normalised fields.

    Use :meth:`predict_displacement` for physical units (Pa, m in; m out).
    """

    def __init__(self, config: CNNConfig | None = None, scales: FieldScales | None = None) -> None:
        super().__init__()
        self.config = config or CNNConfig()
        w, slope = self.config.width, self.config.negative_slope
        self.normalizer = FieldNormalizer(scales or FieldScales())
        n_in = IN_CHANNELS + int(self.config.mask_input)
        if self.config.arch == "unet":
            self.body = UNet3D(n_in, w, self.config.levels, slope)
        else:
            self.stem = ConvAct(n_in, w, 3, slope)
            self.trunk = nn.Sequential(
                *(ConvAct(w, w, 3, slope) for _ in range(self.config.depth - 1))
            )
            self.branch2 = PooledBranch(w, 2, slope)
            self.branch4 = PooledBranch(w, 4, slope)
            self.head = ConvAct(w, w, 1, slope)
        self.out = nn.Conv3d(w, OUT_CHANNELS, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(N, 2, D, H, W) normalised inputs -> (N, 3, D, H, W) normalised displacement."""
        if self.config.mask_input:
            x = torch.cat([x, (x[:, 1:2] > 0).to(x.dtype)], dim=1)  # phi's sign is unscaled
        if self.config.arch == "unet":
            return conv3d_same(self.body(x), self.out.weight, self.out.bias)
        h = self.stem(x)
        y = self.trunk(h) + self.branch2(h) + self.branch4(h)
        return conv3d_same(self.head(y), self.out.weight, self.out.bias)

    def predict_displacement(
        self, pressure_pa: torch.Tensor, level_set_m: torch.Tensor
    ) -> torch.Tensor:
        """(N, D, H, W) absolute pressure in Pa and level set in m -> (N, 3, D, H, W) u in m."""
        x = self.normalizer.encode_inputs(pressure_pa, level_set_m)
        return self.normalizer.decode_displacement(self(x), pressure_pa)

    def constructor_args(self) -> dict[str, Any]:
        """Plain-dict constructor arguments (config and scales) for checkpoints."""
        return {"config": asdict(self.config), "scales": asdict(self.normalizer.scales())}

    @classmethod
    def from_constructor_args(cls, args: dict[str, Any]) -> DisplacementCNN:
        """Inverse of :meth:`constructor_args`."""
        return cls(CNNConfig(**args["config"]), FieldScales(**args["scales"]))

    def with_mask_input(self) -> DisplacementCNN:
        """A copy that also reads the tissue mask and computes exactly what this model does.

        The new channel's stem weights start at zero (fine-tuning then learns them), every other
        weight and the normaliser are copied. A model that already reads the mask is copied as is.
        The paper's layout only (ValueError for a U-Net).
        """
        self._pooled_only("with_mask_input")
        if self.config.mask_input:
            wider = type(self).from_constructor_args(self.constructor_args())
            wider.load_state_dict(self.state_dict())
            return wider
        args = self.constructor_args()
        args["config"] = {**args["config"], "mask_input": True}
        wider = type(self).from_constructor_args(args)
        state = {k: v.clone() for k, v in self.state_dict().items()}
        w = state["stem.conv.weight"]  # (width, 2, k, k, k)
        state["stem.conv.weight"] = torch.cat([w, torch.zeros_like(w[:, :1])], dim=1)
        wider.load_state_dict(state)
        return wider.to(next(self.parameters()).device)

    def widened(self, width: int, *, noise: float = 1e-3, seed: int = 0) -> DisplacementCNN:
        """A copy with ``width`` channels that computes what this model does (Net2WiderNet).

        Every hidden representation (stem, trunk, branches, head) gets the same new channels,
        each a copy of an old one chosen at random; a layer's incoming weights are copied from
        the old channel and its weights from a channel that now has c copies are divided by c,
        so every sum and every leaky ReLU sees what it saw before. The copies' incoming weights
        get Gaussian noise of ``noise`` x that layer's weight RMS, which breaks the symmetry
        that would otherwise keep a copy equal to its original through training (and changes
        the output by about as much). A fine-tune then starts near this model's error with
        more capacity instead of retraining from scratch. The paper's layout only (ValueError
        for a U-Net).
        """
        self._pooled_only("widened")
        old = self.config.width
        if width < old:
            raise ValueError(f"cannot narrow a width-{old} model to {width}")
        gen = torch.Generator().manual_seed(seed)
        source = torch.cat(
            [torch.arange(old), torch.randint(0, old, (width - old,), generator=gen)]
        )
        copies = torch.bincount(source, minlength=old).to(torch.float32)
        args = self.constructor_args()
        args["config"] = {**args["config"], "width": width}
        wide = type(self).from_constructor_args(args)
        state = {k: v.detach().cpu().clone() for k, v in self.state_dict().items()}
        for name, value in list(state.items()):
            if not name.endswith(("weight", "bias")) or name.startswith("normalizer"):
                continue
            if name.endswith("weight") and not name.startswith("stem"):  # in: hidden channels
                value = value[:, source] / copies[source].view(1, -1, *([1] * (value.dim() - 2)))
            if not name.startswith("out."):  # out: hidden channels (the last layer keeps 3)
                value = value[source].clone()
                if name.endswith("weight") and width > old:
                    rms = value[:old].pow(2).mean().sqrt()
                    shape = value[old:].shape
                    value[old:] += noise * rms * torch.randn(shape, generator=gen)
            state[name] = value
        wide.load_state_dict(state)
        return wide.to(next(self.parameters()).device)

    def _pooled_only(self, what: str) -> None:
        if self.config.arch != "pooled":
            raise ValueError(
                f"{what} works on the paper's layout only, not arch {self.config.arch!r}"
            )

    def n_parameters(self) -> int:
        """Number of trainable scalars."""
        return sum(p.numel() for p in self.parameters() if p.requires_grad)
