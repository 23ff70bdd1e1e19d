"""Strain-energy density W, the driver of the cut, and the paper's strain-energy error metric."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from diathermy.fem.elastic import lame_parameters


def strain_energy_density(
    grads: np.ndarray,
    tets: np.ndarray,
    u: np.ndarray,
    youngs_modulus_pa: np.ndarray | float,
    nu: float,
    *,
    gradient: sp.csr_matrix | None = None,
) -> np.ndarray:
    """W = 1/2 eps(u) : C : eps(u) per tet (n_tets,) in J/m^3, of the TOTAL strain.

    PHYSICS.md section 2: the total strain, so free swelling under Delta p stores Delta p^2 / 2K
    (the energy in the pore walls). ``grads`` (n_tets, 4, 3) in 1/m, ``u`` (n_nodes, 3) in m,
    E per tet or one number in Pa: W = lambda/2 tr(eps)^2 + mu eps : eps.

    ``gradient``: the mesh's ``fem.geometry.gradient_matrix`` when ``tets`` is the whole mesh;
    the same numbers about twice as fast (``grads`` and ``tets`` are then not read).
    """
    if gradient is not None:
        G = (gradient @ u).reshape(-1, 3, 3)  # [e, k, i] = du_i / dx_k: W is the same for G^T
    else:
        G = np.matmul(np.swapaxes(u[tets], 1, 2), grads)  # du_i / dx_k; 3x an einsum's speed
    eps = G + np.swapaxes(G, 1, 2)
    eps *= 0.5
    lam, mu = lame_parameters(youngs_modulus_pa, nu)
    trace = eps[:, 0, 0] + eps[:, 1, 1] + eps[:, 2, 2]
    flat = eps.reshape(-1, 9)
    return 0.5 * lam * trace**2 + mu * np.einsum("ei,ei->e", flat, flat)


def relative_strain_energy_error(W: np.ndarray, W_ref: np.ndarray) -> float:
    """sqrt(sum_e (W_e - W_ref_e)^2) / sqrt(sum_e W_ref_e^2): the paper's accuracy metric.

    Shapes must match. When W_ref is all zero the relative error is undefined: it is 0.0 if W is
    all zero too and +inf otherwise (any energy where none should be is infinitely wrong).
    NaN anywhere raises ValueError rather than hide in the sum.
    """
    W = np.asarray(W, dtype=float)
    W_ref = np.asarray(W_ref, dtype=float)
    if W.shape != W_ref.shape:
        raise ValueError(f"shapes differ: {W.shape} vs {W_ref.shape}")
    if not (np.all(np.isfinite(W)) and np.all(np.isfinite(W_ref))):
        raise ValueError("strain energies must be finite")
    num = float(np.linalg.norm(W - W_ref))
    den = float(np.linalg.norm(W_ref))
    if den == 0.0:
        return 0.0 if num == 0.0 else float("inf")
    return num / den
