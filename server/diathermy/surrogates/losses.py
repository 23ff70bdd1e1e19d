"""Losses and error measures of displacement fields, tensors (N, 3, D, H, W)."""

from __future__ import annotations

import torch


def l2_loss(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean squared error over every component and node (the training objective), 0-d tensor."""
    return torch.mean(torch.square(pred.float() - target.float()))


def relative_l2_per_sample(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """||pred - target||_2 / ||target||_2 per sample, (N,); 0/0 counts as 0."""
    diff = (pred.float() - target.float()).flatten(1).norm(dim=1)
    ref = target.float().flatten(1).norm(dim=1)
    return torch.where(ref > 0, diff / ref.clamp_min(torch.finfo(torch.float32).tiny), diff)


def max_abs_per_sample(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """max |pred - target| over nodes and components per sample, (N,)."""
    return (pred.float() - target.float()).abs().flatten(1).amax(dim=1)
