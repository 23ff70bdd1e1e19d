"""The strain-energy density W of grid displacement fields, in torch, for training losses.

The mechanics' definition (``diathermy.physics.strain_energy``: W = lambda/2 tr(eps)^2 +
mu eps:eps of the total strain, per linear tetrahedron) evaluated on the structured Kuhn mesh
(``diathermy.mesh.kuhn_corners``) with autograd, so a loss can be taken on W itself: the paper's
accuracy measure (eq. 20/21). The tets' gradients come from the mesh's own corner table; the
tests check W against the numpy definition on the mesh. E is in units of the tissue's modulus
(1 where the tet is healthy by the engine's rule, ``physics.topology.healthy_tets``, the ersatz
ratio elsewhere), so W is in units of E.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import numpy as np
import torch

from diathermy.fem.elastic import lame_parameters
from diathermy.mesh import Grid, TetMesh, build_tet_mesh
from diathermy.mesh.tet_mesh import kuhn_corners
from diathermy.physics.topology import healthy_tets


def kuhn_gradients(spacing_m: Sequence[float]) -> np.ndarray:
    """Gradients (6, 4, 3) in 1/m of the 4 hat functions of each Kuhn shape; (dx, dy, dz) m."""
    h = np.asarray(spacing_m, dtype=float)
    out = []
    for corners in kuhn_corners():
        x = corners * h  # (4, 3) vertex coordinates
        inv = np.linalg.inv((x[1:] - x[0]).T)  # rows: gradients of barycentrics 1..3
        out.append(np.vstack([-inv.sum(axis=0), inv]))
    return np.array(out)


@lru_cache(maxsize=4)
def _kuhn_mesh(shape: tuple[int, int, int]) -> TetMesh:
    """The Kuhn mesh of a grid of (nz, ny, nx) nodes (unit spacing: the rule needs no lengths)."""
    nz, ny, nx = shape
    return build_tet_mesh(Grid(shape, size_m=(nx - 1.0, ny - 1.0, nz - 1.0)))


class GridStrainEnergy(torch.nn.Module):
    """u (N, 3, D, H, W) m (components x, y, z), phi (N, D, H, W) -> W (N, 6, D-1, H-1, W-1).

    Tet ``(cell k, j, i; shape s)`` is the mesh's tet ``6 * cell + s``: ``W.permute(0, 2, 3, 4,
    1).reshape(N, -1)`` is in the mesh's tet order.
    """

    grads: torch.Tensor  # (6, 4, 3) 1/m, a buffer

    def __init__(
        self, spacing_m: Sequence[float], poisson_ratio: float, ersatz_ratio: float
    ) -> None:
        super().__init__()
        lam, mu = lame_parameters(1.0, poisson_ratio)
        self.lam, self.mu, self.ersatz_ratio = float(lam), float(mu), float(ersatz_ratio)
        self.corners = [tuple(map(tuple, c.tolist())) for c in kuhn_corners()]  # (ox, oy, oz)
        self.register_buffer(
            "grads", torch.tensor(kuhn_gradients(spacing_m), dtype=torch.float32), persistent=False
        )

    @staticmethod
    def _corner(field: torch.Tensor, offset: tuple[int, int, int]) -> torch.Tensor:
        """The value of a nodal field (..., D, H, W) at one corner of every cell (..., D-1, ...)."""
        ox, oy, oz = offset
        d, h, w = field.shape[-3:]
        return field[..., oz : oz + d - 1, oy : oy + h - 1, ox : ox + w - 1]

    @staticmethod
    def healthy_mask(phi: torch.Tensor) -> torch.Tensor:
        """(N, 6, D-1, H-1, W-1) bool: each tet healthy by ``physics.topology.healthy_tets``."""
        d, h, w = phi.shape[-3:]
        mesh = _kuhn_mesh((int(d), int(h), int(w)))
        flat = phi.detach().to("cpu", torch.float64).numpy().reshape(-1, d * h * w)
        masks = np.stack([healthy_tets(row, mesh) for row in flat])
        masks = masks.reshape(-1, d - 1, h - 1, w - 1, 6).transpose(0, 4, 1, 2, 3)
        return torch.from_numpy(np.ascontiguousarray(masks)).to(phi.device)

    def forward(self, u: torch.Tensor, phi: torch.Tensor) -> torch.Tensor:
        u = u.float()
        grads = self.grads
        healthy = self.healthy_mask(phi)
        shapes = []
        for s, corners in enumerate(self.corners):
            # du_i/dx_k = sum_a u_i(vertex a) g[a, k]: (N, 3, 3, D-1, H-1, W-1)
            G = torch.stack(
                [
                    self._corner(u, c)[:, :, None] * grads[s, a].view(1, 1, 3, 1, 1, 1)
                    for a, c in enumerate(corners)
                ]
            ).sum(dim=0)
            eps = 0.5 * (G + G.transpose(1, 2))
            trace = eps[:, 0, 0] + eps[:, 1, 1] + eps[:, 2, 2]
            W = 0.5 * self.lam * trace**2 + self.mu * torch.square(eps).sum(dim=(1, 2))
            shapes.append(torch.where(healthy[:, s], W, self.ersatz_ratio * W))
        return torch.stack(shapes, dim=1)


def relative_strain_energy_error_squared(W: torch.Tensor, W_ref: torch.Tensor) -> torch.Tensor:
    """(sum_e (W - W_ref)^2 / sum_e W_ref^2) per sample (N,): eq. 20/21 squared; 0/0 counts 0."""
    num = torch.square(W - W_ref).flatten(1).sum(dim=1)
    den = torch.square(W_ref).flatten(1).sum(dim=1)
    return torch.where(den > 0, num / den.clamp_min(torch.finfo(torch.float32).tiny), num)
