"""The window's history: the windowed polish solving for past displacements with its window.

What the window cannot reach is the far field: the nodes it holds keep the Ritz-scaled last
displacement, whose shape there is not the new one's. With ``window_history`` m > 0 the
correction is sought in the window's DOFs *and* the span of the last m displacements (global
vectors), jointly: PCG on the coupled system [[A_WW, (AZ)_W], [(AZ)_W^T, I]] with Z the
A-orthonormalised history, preconditioned by the window's V-cycle and the identity. The minimum
over the larger space can only be lower; the far field then follows the history's
shapes (docs/realtime.md, *The window and the history*).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from diathermy.fem.energy_cg import EnergyCG, energy_cg


class PolishWindow(Protocol):
    """What the history needs of ``polish_window.PolishWindow``: its DOFs, its block of A (as
    the fine level of its V-cycle), the product of A with a vector on its DOFs, and its V-cycle."""

    @property
    def dofs(self) -> np.ndarray: ...

    @property
    def preconditioner(self) -> spla.LinearOperator: ...

    def operator(self, A: sp.bsr_matrix) -> sp.bsr_matrix: ...

    def spread(
        self, A: sp.bsr_matrix, delta: np.ndarray, Aw: sp.bsr_matrix | None = None
    ) -> np.ndarray: ...


HISTORY_CUTOFF = 1e-10
"""Directions of the history whose energy is below this x the largest are dropped (the past
displacements are nearly parallel: the Gram matrix is ill-conditioned)."""


@dataclass(frozen=True)
class History:
    """The past displacements in the scaled system, A-orthonormal: Z (n_dofs, k) and A Z."""

    Z: np.ndarray
    AZ: np.ndarray

    @classmethod
    def of(
        cls,
        A: sp.spmatrix,
        scale: np.ndarray,
        displacements: Sequence[np.ndarray],
        window: PolishWindow | None = None,
        first_product: np.ndarray | None = None,
        constrained: np.ndarray | None = None,
    ) -> History:
        """Z spanning the displacements (each (n_nodes, 3) m) seen through the scaling
        x = u / scale; one block product (``first_product``: A x of the first when the caller
        has it, e.g. from the Ritz-scaled start, so the product has one column fewer). With
        ``window``, their values on its DOFs are dropped first: the window's own DOFs span
        those, and without them Z couples to the window only across its boundary (the coupled
        PCG then converges in about the window's iterations; kept whole, 2-3x them).
        ``constrained`` (n_dofs,) bool: DOFs held at zero, zeroed in Z (an answer satisfies
        that already; a product passed in must then be of the zeroed vector)."""
        Y = np.stack([np.ravel(u) / scale for u in displacements], axis=1)
        if constrained is not None:
            Y[constrained] = 0.0
        if first_product is None:
            AY = np.asarray(A @ Y)
        else:
            AY = np.empty_like(Y)
            AY[:, 0] = np.ravel(first_product)
            if Y.shape[1] > 1:
                AY[:, 1:] = np.asarray(A @ Y[:, 1:])
        if window is not None:
            dofs = window.dofs
            for j in range(Y.shape[1]):
                AY[:, j] -= window.spread(A, Y[dofs, j])
            Y[dofs] = 0.0
        G = Y.T @ AY
        w, V = np.linalg.eigh(0.5 * (G + G.T))
        keep = w > HISTORY_CUTOFF * max(float(w.max()), 0.0)
        T = V[:, keep] / np.sqrt(w[keep])
        return cls(Y @ T, AY @ T)

    @property
    def size(self) -> int:
        return int(self.Z.shape[1])


def augmented_correct(
    window: PolishWindow,
    A: sp.bsr_matrix,
    history: History,
    residual: np.ndarray,
    norm_sq: float,
    *,
    tol: float,
    maxiter: int,
) -> tuple[EnergyCG, np.ndarray]:
    """``window_correct`` over the window's DOFs and the history's span together: PCG on the
    coupled system from zero; (the PCG result for the window's part, the history's
    coefficients c, so that the correction is delta_W + Z c)."""
    dofs = window.dofs
    n_w, k = dofs.size, history.size
    Aw = window.operator(A)
    AZ_w = history.AZ[dofs]
    M_w = window.preconditioner

    def apply(v: np.ndarray) -> np.ndarray:
        d, c = v[:n_w], v[n_w:]
        return np.concatenate([Aw @ d + AZ_w @ c, AZ_w.T @ d + c])

    def precondition(v: np.ndarray) -> np.ndarray:
        return np.concatenate([M_w @ v[:n_w], v[n_w:]])

    shape = (n_w + k, n_w + k)
    res = energy_cg(
        spla.LinearOperator(shape, matvec=apply, dtype=float),
        np.concatenate([residual[dofs], history.Z.T @ residual]),
        np.zeros(n_w + k),
        spla.LinearOperator(shape, matvec=precondition, dtype=float),
        tol=tol,
        maxiter=maxiter,
        norm_sq=norm_sq,
    )
    return (
        EnergyCG(res.x[:n_w], res.iterations, res.estimate, res.residual),
        res.x[n_w:],
    )
