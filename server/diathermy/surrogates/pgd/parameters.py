"""The PGD's pressure parameter p = (Q, r): an overpressure field reduced to its first two moments.

Why these two: elastostatics is linear in the load, and the load of a pore overpressure Delta p
is an eigenstress. Far from the source the displacement is that of a centre of dilatation of
strength Q = int_healthy Delta p dV (Pa m^3) -- the zeroth moment; the near field, where the
strain energy that drives the cut lives, depends on how far the overpressure spreads -- the RMS
radius r about the contact point (second moment). So u = Q * U(x; s, r, g) exactly in Q, and the
reduced model only has to learn the shape U of a unit-strength source of radius r. Training loads
are isotropic Gaussian bumps exp(-|x - c|^2 / r^2) normalised to Q = 1, whose RMS radius is
sqrt(3/2) r in the continuum; a measured field is mapped to the bump of equal strength and
equal discrete RMS radius (``equivalent_radius``).
"""

from __future__ import annotations

import numpy as np


def healthy_node_weights(
    tets: np.ndarray, volumes: np.ndarray, healthy: np.ndarray, n_nodes: int
) -> np.ndarray:
    """Quadrature weights (n_nodes,) in m^3 of int_healthy f dV for nodal P1 f: a quarter per tet."""
    vol = np.where(np.asarray(healthy, dtype=bool), volumes, 0.0)
    return np.bincount(tets.ravel(), np.repeat(vol / 4.0, 4), minlength=n_nodes)


def bump_pressure(
    points: np.ndarray, centre: np.ndarray, radius_m: float, weights: np.ndarray
) -> np.ndarray:
    """Overpressure (n_nodes,) in Pa of unit strength: exp(-|x - c|^2 / r^2) scaled so sum w dp = 1.

    ``points`` (n_nodes, 3) m, ``centre`` (3,) m, ``weights`` (n_nodes,) m^3 from
    ``healthy_node_weights``. All zero when no healthy node carries the bump.
    """
    d2 = np.sum((points - np.asarray(centre, dtype=float)) ** 2, axis=1)
    bump = np.exp(-d2 / radius_m**2)
    q = float(np.dot(weights, bump))
    return bump / q if q > 0 else np.zeros_like(bump)


def pressure_moments(
    overpressure_pa: np.ndarray, points: np.ndarray, centre: np.ndarray, weights: np.ndarray
) -> tuple[float, float]:
    """(Q in Pa m^3, RMS distance about ``centre`` in m) of a nodal overpressure (n_nodes,).

    Only the positive part counts (vapour pressure is never below p0); (0, 0) when Q = 0.
    """
    dp = np.maximum(np.asarray(overpressure_pa, dtype=float), 0.0)
    wdp = weights * dp
    q = float(wdp.sum())
    if q <= 0.0:
        return 0.0, 0.0
    d2 = np.sum((points - np.asarray(centre, dtype=float)) ** 2, axis=1)
    return q, float(np.sqrt(np.dot(wdp, d2) / q))


def equivalent_radius(
    rms_m: float,
    points: np.ndarray,
    centre: np.ndarray,
    weights: np.ndarray,
    r_range: tuple[float, float],
) -> float:
    """Bump radius r whose *discrete* bump at ``centre`` has RMS distance ``rms_m``.

    On the mesh the RMS of exp(-d^2/r^2) is not exactly sqrt(3/2) r (nodes, cut, block edges),
    so r is found by bisection on the discrete moment (monotone in r); a training bump thus maps
    back to its own grid radius. Outside ``r_range`` the continuum ratio extrapolates.
    """
    d2 = np.sum((points - np.asarray(centre, dtype=float)) ** 2, axis=1)

    def rms(r: float) -> float:
        b = weights * np.exp(-d2 / r**2)
        q = b.sum()
        return float(np.sqrt(np.dot(b, d2) / q)) if q > 0 else 0.0

    lo, hi = float(r_range[0]), float(r_range[1])
    rms_lo, rms_hi = rms(lo), rms(hi)
    if rms_m <= rms_lo:
        return lo * rms_m / rms_lo if rms_lo > 0 else lo
    if rms_m >= rms_hi:
        return hi * rms_m / rms_hi
    for _ in range(60):  # bisection to ~1e-18 relative of the bracket
        mid = 0.5 * (lo + hi)
        if rms(mid) < rms_m:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
