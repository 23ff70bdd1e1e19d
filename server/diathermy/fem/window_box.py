"""Boxes of nodes around where a step changed: the windows the incremental solves work on."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class WindowBox:
    """The window's box (lo, hi) and the inner box the change may move in before a new window,
    each corner (3,) in m."""

    lo: np.ndarray
    hi: np.ndarray
    inner_lo: np.ndarray
    inner_hi: np.ndarray

    def holds(self, lo: np.ndarray, hi: np.ndarray) -> bool:
        """Whether a change inside [lo, hi] may keep this window."""
        return bool(np.all(lo >= self.inner_lo) and np.all(hi <= self.inner_hi))

    def as_array(self) -> np.ndarray:
        """(4, 3): lo, hi, inner lo, inner hi (what a checkpoint stores)."""
        return np.stack([self.lo, self.hi, self.inner_lo, self.inner_hi])

    @classmethod
    def from_array(cls, a: np.ndarray) -> WindowBox:
        a = np.asarray(a, dtype=float).reshape(4, 3)
        return cls(a[0].copy(), a[1].copy(), a[2].copy(), a[3].copy())


def nodes_in_box(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Indices of the points (n, 3) m inside the closed box [lo, hi], ascending (one axis at a
    time, each on the points the axes before kept)."""
    z = points[:, 2]
    idx = np.flatnonzero((z >= lo[2]) & (z <= hi[2]))
    for k in (1, 0):
        c = points[idx, k]
        idx = idx[(c >= lo[k]) & (c <= hi[k])]
    return idx


def choose_box(
    points: np.ndarray, change: np.ndarray, margin_m: float, max_nodes: int
) -> WindowBox:
    """The box around the nodes ``change`` grown by ``margin_m`` on every side, the margin halved
    until at most ``max_nodes`` nodes lie inside (down to the change's own box); the inner box
    is grown by half the margin used."""
    P = points[change]
    lo, hi = P.min(axis=0), P.max(axis=0)
    margin = float(margin_m)
    while margin > 0 and nodes_in_box(points, lo - margin, hi + margin).size > max_nodes:
        margin = margin / 2 if margin > 1e-4 else 0.0
    return WindowBox(lo - margin, hi + margin, lo - margin / 2, hi + margin / 2)
