"""Strain-energy density W, the driver of the cut, and the paper's strain-energy error metric."""

from __future__ import annotations

import numpy as np

from diathermy.fem.elastic import lame_parameters
from diathermy.mesh.grid import Grid
from diathermy.mesh.kuhn_fields import axis_differences, per_tet, shape_gradient, shapes_last


def strain_energy_density(
    grads: np.ndarray,
    tets: np.ndarray,
    u: np.ndarray,
    youngs_modulus_pa: np.ndarray | float,
    nu: float,
) -> np.ndarray:
    """W = 1/2 eps(u) : C : eps(u) per tet (n_tets,) in J/m^3, of the TOTAL strain.

    PHYSICS.md section 2: the total strain, so free swelling under Delta p stores Delta p^2 / 2K
    (the energy in the pore walls). ``grads`` (n_tets, 4, 3) in 1/m, ``u`` (n_nodes, 3) in m,
    E per tet or one number in Pa: W = lambda/2 tr(eps)^2 + mu eps : eps. On a whole Kuhn mesh
    ``kuhn_strain_energy_density`` gives the same numbers faster.
    """
    G = np.matmul(np.swapaxes(u[tets], 1, 2), grads)  # du_i / dx_k; 3x an einsum's speed
    lam, mu = lame_parameters(youngs_modulus_pa, nu)
    return _energy([[G[:, k, i] for i in range(3)] for k in range(3)], lam, mu)


def _energy(G: list[list[np.ndarray]], lam: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """W = lambda/2 tr(eps)^2 + mu eps : eps from the displacement gradient G[k][i] = du_i/dx_k
    (arrays of one shape), eps = (G + G^T) / 2, so eps : eps = sum_i G_ii^2 + 1/2 sum_{i<k}
    (G_ik + G_ki)^2."""
    trace = G[0][0] + G[1][1] + G[2][2]
    shear = (G[0][1] + G[1][0]) ** 2 + (G[0][2] + G[2][0]) ** 2 + (G[1][2] + G[2][1]) ** 2
    eps_eps = G[0][0] ** 2 + G[1][1] ** 2 + G[2][2] ** 2 + 0.5 * shear
    return 0.5 * lam * trace**2 + mu * eps_eps


def kuhn_strain_energy_density(
    u: np.ndarray, grid: Grid, youngs_modulus_pa: np.ndarray | float, nu: float
) -> np.ndarray:
    """``strain_energy_density`` of every tet of the Kuhn mesh of ``grid`` (TetMesh order: tet
    6 cell + s), u (n_nodes, 3) in m, E per tet or one number in Pa, from node differences
    (``mesh.kuhn_fields``: 21 ms on the fixed electrode's 958 k tets, where the product with a
    stored gradient matrix took 113 ms)."""
    u = np.asarray(u, dtype=float)
    diffs = [axis_differences(u[:, i], grid) for i in range(3)]  # [i][k]: du_i / dx_k
    lam, mu = lame_parameters(youngs_modulus_pa, nu)
    lam_s, mu_s = per_tet(lam, grid), per_tet(mu, grid)
    out = np.empty((6, *lam_s.shape[:3]))
    for s in range(6):
        by_component = [shape_gradient(d, s) for d in diffs]  # [i][k]
        G = [[by_component[i][k] for i in range(3)] for k in range(3)]  # [k][i]
        out[s] = _energy(G, lam_s[..., s], mu_s[..., s])
    return shapes_last(out)


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
