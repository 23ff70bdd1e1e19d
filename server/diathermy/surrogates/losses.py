"""Losses and error measures of displacement fields, tensors (N, 3, D, H, W)."""

from __future__ import annotations

import torch

from diathermy.surrogates.strain_energy import (
    GridStrainEnergy,
    relative_strain_energy_error_squared,
)


def l2_loss(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean squared error over every component and node (the training objective), 0-d tensor."""
    return torch.mean(torch.square(pred.float() - target.float()))


def relative_l2_per_sample(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """||pred - target||_2 / ||target||_2 per sample, (N,); 0/0 counts as 0."""
    diff = (pred.float() - target.float()).flatten(1).norm(dim=1)
    ref = target.float().flatten(1).norm(dim=1)
    return torch.where(ref > 0, diff / ref.clamp_min(torch.finfo(torch.float32).tiny), diff)


def training_loss(
    pred: torch.Tensor,
    target: torch.Tensor,
    strain_weight: float,
    energy_weight: float = 0.0,
    strain_energy: GridStrainEnergy | None = None,
    level_set: torch.Tensor | None = None,
) -> torch.Tensor:
    """L2 displacement loss + ``strain_weight`` x the error of the forward differences
    + ``energy_weight`` x the batch mean of the squared relative strain-energy error, 0-d.

    The strain-energy error the model is judged by lives in the displacement's gradients, which
    a plain L2 loss weighs little. The mean squared error of the differences along z, y and x
    (the discrete strain) is rescaled by the batch's mean(u^2) / mean(|D u|^2), so that a weight
    of 1 makes a relative gradient error count like a relative displacement error.

    The energy term is the accuracy measure itself (eq. 20/21, squared), W per tet of the mesh
    by ``strain_energy`` under ``level_set`` (N, D, H, W): it weighs the tets by their energy,
    so the soft removed tissue in a crater, whose displacement is large but stores almost
    nothing, stops dominating the loss as it does the L2 term.
    """
    loss = l2_loss(pred, target)
    if energy_weight != 0.0:
        if strain_energy is None or level_set is None:
            raise ValueError("the energy term needs strain_energy and level_set")
        W = strain_energy(pred, level_set)
        W_ref = strain_energy(target.detach(), level_set)
        loss = loss + energy_weight * relative_strain_energy_error_squared(W, W_ref).mean()
    if strain_weight == 0.0:
        return loss
    p, t = pred.float(), target.float()
    err = torch.zeros((), device=p.device)
    ref = torch.zeros((), device=p.device)
    for d in (2, 3, 4):
        dt = torch.diff(t, dim=d)
        err = err + torch.mean(torch.square(torch.diff(p, dim=d) - dt))
        ref = ref + torch.mean(torch.square(dt.detach()))
    u2 = torch.mean(torch.square(t.detach()))
    ratio = torch.where(ref > 0, u2 / ref.clamp_min(1e-30), torch.ones_like(u2))
    return loss + strain_weight * ratio * err
