"""The level set that cuts the tissue (PHYSICS.md section 4): speed law, upwind advance, re-init.

phi lives on the structured nodes as an array shaped (nz, ny, nx); phi > 0 is healthy tissue,
phi < 0 removed. The front moves into the tissue with normal speed F >= 0:

    phi_t + F |grad phi| = 0,    F = v0 max(0, W / kappa - 1).

Irreversibility: ``advance`` never increases phi at any node (F >= 0), and ``reinitialize``
(``physics.reinitialize``, re-exported here) keeps the sign of every node and never raises phi
at a node that can move the cut (see there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import numpy as np
import scipy.sparse as sp

from diathermy.errors import SolverDivergedError
from diathermy.mesh.grid import Grid
from diathermy.physics import levelset_graded as graded
from diathermy.physics.levelset_graded import CellSizes
from diathermy.physics.levelset_law import CFL, MAX_SUBSTEPS, V0_M_PER_S
from diathermy.physics.reinitialize import reinitialize as reinitialize  # re-exported

Spacing = tuple[float, float, float]
"""Node spacing (dx, dy, dz) in m, the order of ``Grid.spacing_m``; arrays are (z, y, x)."""


def grid_spacing(grid: Grid) -> Spacing | CellSizes:
    """What ``advance`` and ``reinitialize`` take for a grid: its spacing (dx, dy, dz) in m if
    uniform, else its cell lengths per axis (``Grid.cell_sizes_m()``)."""
    return grid.spacing_m if grid.is_uniform else grid.cell_sizes_m()


@dataclass(frozen=True)
class LevelSetStep:
    """What one ``advance`` did: new phi (nz, ny, nx) in m, sub-steps taken, their dt in s,
    and how many nodes had F > 0 (the only nodes that can change)."""

    phi: np.ndarray
    n_substeps: int
    dt_sub_s: float
    n_active: int


def initial_level_set(grid: Grid) -> np.ndarray:
    """Signed distance (nz, ny, nx) in m to the traction-free top surface: phi = z_top - z."""
    z = grid.axes()[2]
    return np.broadcast_to((z[-1] - z)[:, None, None], grid.shape).copy()


def front_speed(W_nodes: np.ndarray, kappa: float, v0: float = V0_M_PER_S) -> np.ndarray:
    """Normal front speed F = v0 max(0, W / kappa - 1) in m/s, same shape as W (J/m^3).

    kappa is the damage threshold in J/m^3, v0 the speed scale in m/s. The one place of this law.
    """
    if not kappa > 0:
        raise ValueError(f"kappa must be positive, got {kappa}")
    return v0 * np.maximum(0.0, np.asarray(W_nodes, dtype=float) / kappa - 1.0)


def tet_to_node(
    values_per_tet: np.ndarray,
    tets: np.ndarray,
    volumes: np.ndarray,
    n_nodes: int,
    *,
    include: np.ndarray | None = None,
    incidence: sp.csr_matrix | None = None,
) -> np.ndarray:
    """Volume-weighted mean (n_nodes,) of a per-tet field (n_tets,) over the tets around each node.

    This is the lumped-mass L2 projection of the piecewise-constant field onto P1, so it converges
    with the mesh and conserves the integral. A max over the adjacent tets would instead paint
    every node of the single most-strained tet (and so a whole cell layer) with the peak W, biasing
    the cut upward by O(h) and making the onset grid-dependent.

    Args:
        values_per_tet: e.g. W in J/m^3; volumes: tet volumes (n_tets,) in m^3.
        include: optional mask (n_tets,) of the tets to average over; pass ~removed so that the
            near-zero W of removed (ersatz) tets does not dilute W on the cut surface. Nodes with
            no included tet get 0.
        incidence: ``volume_incidence(tets, volumes, n_nodes)``, built once per mesh, turns the
            two scatter-adds into sparse products (~7x faster on the full grid).
    """
    vw = np.asarray(values_per_tet, dtype=float)
    w = np.ones(vw.shape) if include is None else np.asarray(include, dtype=float)
    if incidence is not None:
        num, den = incidence @ (vw * w), incidence @ w
    else:
        flat, vol = tets.reshape(-1), np.asarray(volumes, dtype=float)
        num = np.bincount(flat, np.repeat(vol * w * vw, 4), n_nodes)
        den = np.bincount(flat, np.repeat(vol * w, 4), n_nodes)
    return np.divide(num, den, out=np.zeros(n_nodes), where=den > 0)


def volume_incidence(tets: np.ndarray, volumes: np.ndarray, n_nodes: int) -> sp.csr_matrix:
    """Sparse (n_nodes, n_tets) with the tet volume (m^3) at each (node of tet, tet) pair."""
    rows = tets.reshape(-1)
    cols = np.repeat(np.arange(tets.shape[0]), 4)
    vol = np.repeat(np.asarray(volumes, dtype=float), 4)
    return sp.csr_matrix((vol, (rows, cols)), shape=(n_nodes, tets.shape[0]))


@dataclass(frozen=True)
class _Stencil:
    """Flat indices of the active nodes and of their -/+ neighbours per axis (z, y, x).

    At a block face the missing neighbour is replaced by linear extrapolation (ghost = 2 phi_c -
    phi_inner), i.e. both one-sided differences there are the inner one, the ghost's capped at
    ``GHOST_SLOPE_CAP``.
    """

    center: np.ndarray
    minus: tuple[np.ndarray, ...]
    plus: tuple[np.ndarray, ...]
    at_lo: tuple[np.ndarray, ...]
    at_hi: tuple[np.ndarray, ...]


GHOST_SLOPE_CAP = 1.0
"""Largest slope of phi (m/m) a face's ghost node extrapolates: a signed distance's, so a front
entering through a face moves at F, and a face node cannot run away from the interior."""


def _stencil(shape: tuple[int, ...], active: np.ndarray) -> _Stencil:
    strides = (shape[1] * shape[2], shape[2], 1)
    minus, plus, at_lo, at_hi = [], [], [], []
    for n, s in zip(shape, strides, strict=True):
        c = (active // s) % n
        lo, hi = c == 0, c == n - 1
        minus.append(np.where(lo, active + s, active - s))
        plus.append(np.where(hi, active - s, active + s))
        at_lo.append(lo)
        at_hi.append(hi)
    return _Stencil(active, tuple(minus), tuple(plus), tuple(at_lo), tuple(at_hi))


def _godunov_gradient(flat: np.ndarray, st: _Stencil, h_zyx: Spacing) -> np.ndarray:
    """|grad phi| at the active nodes, Godunov upwind for F >= 0.

    Per axis r = max(D-, -D+, 0), |grad phi|^2 = sum r^2: the exact Godunov flux of the convex
    F |p|. (Osher–Sethian's sum max(D-,0)^2 + min(D+,0)^2 differs only at a local maximum of phi
    along an axis; the max form is monotone for CFL <= 1 at any aspect ratio.)
    """
    pc = flat[st.center]
    g2 = np.zeros(pc.shape)
    for h, im, ip, lo, hi in zip(h_zyx, st.minus, st.plus, st.at_lo, st.at_hi, strict=True):
        pm, pp = flat[im], flat[ip]
        # Ghost slopes are capped at GHOST_SLOPE_CAP: uncapped, a face node whose inner
        # neighbour lags falls by a factor (1 + dt_sub F / h) per sub-step (-1e81 m in one 1 s step).
        d_minus = np.where(lo, np.minimum(pp - pc, GHOST_SLOPE_CAP * h), pc - pm) / h
        d_plus = np.where(hi, np.maximum(pc - pm, -GHOST_SLOPE_CAP * h), pp - pc) / h
        g2 += np.maximum(np.maximum(d_minus, -d_plus), 0.0) ** 2
    return np.sqrt(g2)


def substeps_needed(F_max: float, spacing: Spacing, dt: float, cfl: float) -> int:
    """Smallest n >= 1 with (dt / n) F_max (1/dx + 1/dy + 1/dz) <= cfl."""
    return _substeps(F_max * sum(1.0 / h for h in spacing), dt, cfl)


def _substeps(rate: float, dt: float, cfl: float) -> int:
    """Smallest n >= 1 with (dt / n) rate <= cfl, rate = max F sum_a 1/h_a in 1/s."""
    n = max(1, math.ceil(dt * rate / cfl))
    while dt / n * rate > cfl:  # ceil of a rounded quotient can fall one short
        n += 1
    return n


def advance(
    phi: np.ndarray,
    F: np.ndarray,
    spacing: Spacing | CellSizes,
    dt: float,
    *,
    cfl: float = CFL,
    max_substeps: int = MAX_SUBSTEPS,
) -> LevelSetStep:
    """Advance phi_t + F |grad phi| = 0 by dt seconds with F >= 0 (m/s); returns a new phi.

    Explicit Godunov upwind in space, forward Euler in time, in equal sub-steps that respect
    dt_sub max F (1/dx + 1/dy + 1/dz) <= cfl. Why this is monotone and irreversible: each update is
    phi_c - dt_sub F g(phi_c - phi_nb) with g non-decreasing in phi_c - phi_nb; its derivative in
    phi_c is 1 - dt_sub F sum_a (r_a / h_a) / |r| >= 1 - cfl >= 0 and in each neighbour >= 0, so
    no new extrema appear, and F >= 0, g >= 0 give phi_new <= phi (enforced by a min against
    round-off all the same). At a block face the missing neighbour is a linearly extrapolated
    ghost, so a front can enter through a face (the top); there the bound holds with respect to the
    ghost values, whose slope is capped at ``GHOST_SLOPE_CAP`` (the ghost term decreases as phi_c
    does, so uncapped it would grow geometrically over the sub-steps). Nodes with F = 0 do not change, so only nodes with F > 0 are updated (their
    neighbours are read); a step with F = 0 everywhere returns an exact copy.

    Args:
        phi: level set (nz, ny, nx) in m, every axis >= 2 nodes.
        F: front speed in m/s, phi's shape or flat (nz*ny*nx,).
        spacing: (dx, dy, dz) in m, or on a graded grid the cell lengths per axis (dx (nx-1,),
            dy, dz): one-sided differences over the node's own spacings, and the CFL limit
            from each active node's smaller spacing per axis (``grid_spacing(grid)``).
        dt: physical step in s.

    Raises:
        SolverDivergedError: F or phi not finite, or more than ``max_substeps`` sub-steps needed.
    """
    phi = np.asarray(phi, dtype=float)
    if phi.ndim != 3 or min(phi.shape) < 2:
        raise ValueError(f"phi must be (nz, ny, nx) with >= 2 nodes per axis, got {phi.shape}")
    F = np.asarray(F, dtype=float).reshape(phi.shape)
    if not (dt >= 0 and math.isfinite(dt)):
        raise ValueError(f"dt must be finite and >= 0, got {dt}")
    if not 0 < cfl <= 1:
        raise ValueError(f"cfl must lie in (0, 1], got {cfl}")
    F_max = float(F.max())
    if not math.isfinite(F_max):  # max propagates NaN
        raise SolverDivergedError(f"level-set speed is not finite (max F = {F_max} m/s)")
    if F.min() < 0:
        raise ValueError(f"front speed must be >= 0, got min F = {F.min()} m/s")
    out = phi.copy()
    active = np.flatnonzero(F)
    if active.size == 0 or dt == 0:
        return LevelSetStep(out, 0, 0.0, int(active.size))
    if graded.is_graded(spacing):
        h_minus, h_plus = graded.node_spacings(phi.shape, active, spacing)  # type: ignore[arg-type]
        n_sub = _substeps(graded.cfl_rate(F.reshape(-1)[active], h_minus, h_plus), dt, cfl)
    else:
        n_sub = substeps_needed(F_max, spacing, dt, cfl)  # type: ignore[arg-type]
    if n_sub > max_substeps:
        raise SolverDivergedError(
            f"level set needs {n_sub} sub-steps (> {max_substeps}) for max F = {F_max:.3g} m/s "
            f"over dt = {dt:.3g} s; the speed is absurd (is W finite and in J/m^3?)"
        )
    flat = out.reshape(-1)
    if not np.all(np.isfinite(flat[active])):
        raise SolverDivergedError("level set phi is not finite where F > 0")
    dt_sub = dt / n_sub
    st = _stencil(phi.shape, active)
    rate = dt_sub * F.reshape(-1)[active]
    if graded.is_graded(spacing):
        for _ in range(n_sub):
            old = flat[active]
            g = graded.godunov_gradient(
                flat,
                st.center,
                st.minus,
                st.plus,
                st.at_lo,
                st.at_hi,
                h_minus,
                h_plus,
                GHOST_SLOPE_CAP,
            )
            flat[active] = np.minimum(old - rate * g, old)
        return LevelSetStep(out, n_sub, dt_sub, int(active.size))
    h = cast(Spacing, spacing)
    h_zyx = (h[2], h[1], h[0])
    for _ in range(n_sub):
        old = flat[active]
        flat[active] = np.minimum(old - rate * _godunov_gradient(flat, st, h_zyx), old)
    return LevelSetStep(out, n_sub, dt_sub, int(active.size))
