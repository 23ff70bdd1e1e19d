"""Analytic resistance of the active electrode's contact (PHYSICS.md 1, 6a): references for the
delivered power P = I^2 R of a resolved contact.

A disk of radius a on a half-space of conductivity sigma:
- equipotential disk (a perfectly conducting electrode): R = 1 / (4 sigma a);
- uniform current density over the disk (the current-density drive): P = int j V = I <V>, with
  the disk's mean potential <V> = 8 I / (3 pi^2 sigma a), so R = 8 / (3 pi^2 sigma a), 8 % more
  (the equipotential disk dissipates least, Thomson's principle).
The finite block adds the regular part of its Green's function at the contact
(``block_image_resistance``): grounded bottom and insulated sides by the method of images.
"""

from __future__ import annotations

import numpy as np


def equipotential_disk_resistance(sigma_s_per_m: float, radius_m: float) -> float:
    """R = 1 / (4 sigma a) in ohm: an equipotential disk on a half-space."""
    return 1.0 / (4.0 * sigma_s_per_m * radius_m)


def uniform_flux_disk_resistance(sigma_s_per_m: float, radius_m: float) -> float:
    """R = 8 / (3 pi^2 sigma a) in ohm: P / I^2 of a uniform current density over the disk."""
    return 8.0 / (3.0 * np.pi**2 * sigma_s_per_m * radius_m)


def block_image_resistance(
    sigma_s_per_m: float,
    size_m: tuple[float, float, float],
    origin_m: tuple[float, float, float],
    contact_xy_m: tuple[float, float],
    *,
    n_lateral: int = 8,
    n_vertical: int = 400,
) -> float:
    """The block's own resistance beyond the half-space's, in ohm, for a point contact on top.

    Images of a source on the top face of [x0, x0+Lx] x [y0, y0+Ly] x [z0, z0+H], grounded at
    the bottom, insulated elsewhere: lateral offsets 2 m L and 2 m L - 2 (x - x0) (same sign),
    vertical offsets 2 k H with sign (-1)^k, each of potential I / (2 pi sigma d). The vertical
    sums alternate (partial sums averaged), so the lateral ones decay like exp(-pi d / 2H).
    """
    (lx, ly, h), (x0, y0, _) = size_m, origin_m
    m = np.arange(-n_lateral, n_lateral + 1, dtype=float)
    dx = np.concatenate([2 * m * lx, 2 * m * lx - 2 * (contact_xy_m[0] - x0)])
    dy = np.concatenate([2 * m * ly, 2 * m * ly - 2 * (contact_xy_m[1] - y0)])
    rho2 = (dx[:, None] ** 2 + dy[None, :] ** 2).ravel()
    k = np.arange(-n_vertical, n_vertical + 1, dtype=float)
    sign = np.where(np.abs(k) % 2 == 0, 1.0, -1.0)
    d2 = rho2[:, None] + (2.0 * k * h)[None, :] ** 2
    self_term = d2 == 0.0
    terms = np.where(self_term, 0.0, sign / np.sqrt(np.where(self_term, 1.0, d2)))
    full = terms.sum(axis=1)
    edge = terms[:, 0] + terms[:, -1]  # the two outermost (equal-sign) terms
    averaged = full - 0.5 * edge  # mean of the partial sums up to n_vertical - 1 and n_vertical
    return float(averaged.sum() / (2.0 * np.pi * sigma_s_per_m))
