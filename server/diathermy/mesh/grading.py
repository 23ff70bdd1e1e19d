"""Node coordinates of one axis graded geometrically around a working interval.

Inside the working interval [a, b] the cells are uniform, at most ``fine`` long; away from it
they grow by at most ``growth`` per cell (capped at ``max_cell``) until the block's end. Used by
``Grid.graded`` to put resolution under the electrode and keep the far field coarse.
"""

from __future__ import annotations

import math

import numpy as np

from diathermy.errors import MeshError

MAX_AXIS_NODES = 4096
"""Most nodes one graded axis may get (a guard against a fine spacing that would exhaust memory)."""

MAX_GROWTH = 2.0
"""Largest growth ratio of adjacent cells accepted (P1 accuracy degrades beyond it)."""


def _check_length(name: str, value: float) -> float:
    v = float(value)
    if not math.isfinite(v) or v <= 0.0:
        raise MeshError(f"{name} must be a positive finite length in m, got {value!r}")
    return v


def _outer_cells(gap: float, first: float, growth: float, max_cell: float) -> np.ndarray:
    """Cell lengths (m,) filling ``gap`` outward from a cell of length ``first``.

    The cells grow by one ratio q in [1, growth] (capped at ``max_cell``) chosen so they add up to
    ``gap`` exactly; a gap too short for growth gets equal cells no longer than ``first``.
    """
    if gap <= 0.0:
        return np.zeros(0)

    def cells(q: float, m: int) -> np.ndarray:
        with np.errstate(over="ignore"):  # q^m past the float range is capped anyway
            return np.minimum(first * q ** np.arange(1, m + 1, dtype=float), max(max_cell, first))

    # fewest cells that reach the gap at the largest allowed growth
    total, m, c = 0.0, 0, first
    while total < gap:
        m += 1
        c = min(c * growth, max(max_cell, first))
        total += c
        if m > MAX_AXIS_NODES:
            raise MeshError(
                f"grading needs more than {MAX_AXIS_NODES} cells to fill {gap} m from "
                f"{first} m cells: coarsen the fine spacing or raise the growth ratio"
            )
    if m * first >= gap:
        return np.full(m, gap / m)
    lo, hi = 1.0, growth
    for _ in range(100):  # bisection: the sum grows with q
        mid = 0.5 * (lo + hi)
        if cells(mid, m).sum() < gap:
            lo = mid
        else:
            hi = mid
    out = cells(hi, m)
    return out * (gap / out.sum())


def _lower_cells(
    gap: float, first: float, growth: float, max_cell: float, tier: tuple[float, float] | None
) -> np.ndarray:
    """Cell lengths (m,) filling ``gap`` outward from a cell of length ``first``: over at least
    the tier's length (whole cells growing by ``growth`` up to its cell), then on to
    ``max_cell``; a tier that reaches within one of its cells of the gap's end takes it all."""
    if tier is None:
        return _outer_cells(gap, first, growth, max_cell)
    length = _check_length("tier length", tier[0])
    cell = _check_length("tier cell", tier[1])
    if cell < first * (1.0 - 1e-12) or cell > max_cell:
        raise MeshError(
            f"tier cell ({cell} m) must lie between the fine spacing {first} m and the largest "
            f"cell {max_cell} m"
        )
    near: list[float] = []
    c, total = first, 0.0
    while total < length * (1.0 - 1e-12) and total < gap:
        c = min(c * growth, cell)
        near.append(c)
        total += c
        if len(near) > MAX_AXIS_NODES:
            raise MeshError(
                f"a tier of {length} m in cells of {cell} m needs more than {MAX_AXIS_NODES} cells"
            )
    if gap - total < cell:  # the tier reaches the block's end (no sliver below it)
        return _outer_cells(gap, first, growth, cell)
    return np.concatenate([near, _outer_cells(gap - total, near[-1], growth, max_cell)])


def refined_end(length: float, fine: float, end: float, growth: float) -> np.ndarray:
    """Cell lengths (m,) filling ``length``, shrinking toward the high end by one ratio of at
    most ``growth`` to ``end`` there, at most ``fine`` elsewhere (equal cells when ``end`` is
    ``fine``). The sequence end, end growth, ... is followed by equal cells of at most ``fine``
    that take the rest; where that would break the growth ratio, the sequence (then ``fine``)
    is cut where it covers the length and scaled down to it, so no cell exceeds ``fine`` and the
    end cell not ``end``."""
    if end >= fine * (1.0 - 1e-12):
        n = max(1, math.ceil(length / fine * (1.0 - 1e-12)))
        return np.full(n, length / n)
    if growth <= 1.0:  # no grading allowed: end-sized cells throughout
        n = max(1, math.ceil(length / end * (1.0 - 1e-12)))
        return np.full(n, length / n)
    steps = max(1, math.ceil(math.log(fine / end) / math.log(growth) - 1e-9))
    # each graded cell is at least ``end``: more than length / end of them cover the length and
    # are cut below anyway (a growth a rounding error above 1 asked for 3e15 cells)
    steps = min(steps, math.ceil(length / end) + 1)
    graded = np.minimum(end * growth ** np.arange(steps, dtype=float), fine)
    covered = np.cumsum(graded)
    if covered[-1] >= length * (1.0 - 1e-12):
        cells = graded[: int(np.searchsorted(covered, length * (1.0 - 1e-12))) + 1]
    else:
        rest = length - covered[-1]
        n = math.ceil(rest / fine * (1.0 - 1e-12))
        if rest / n * growth >= graded[-1]:  # equal cells take the rest: the end cell exact
            return np.concatenate([np.full(n, rest / n), graded[::-1]])
        cells = np.concatenate([graded, np.full(n, fine)])
    return (cells * (length / cells.sum()))[::-1]


def graded_axis(
    lo: float,
    hi: float,
    region: tuple[float, float],
    fine: float,
    growth: float,
    max_cell: float = math.inf,
    hi_cell: float | None = None,
    lo_tier: tuple[float, float] | None = None,
) -> np.ndarray:
    """Node coordinates (n,) from lo to hi, uniform (<= fine) on ``region``, geometric outside.

    ``region`` (a, b) with a <= b is clipped to [lo, hi]; a region shorter than one fine cell
    (e.g. a point) becomes the fine cell centred on it. A gap shorter than one fine cell between
    the region and the block's end joins the region, so no sliver cell is left at the boundary.
    ``hi_cell`` (m, at most ``fine``): the region's cells shrink toward its high end to this
    length there, by at most ``growth`` per cell (``refined_end``; e.g. the top surface); the
    cells outside the region grow from its end cells.
    ``lo_tier`` (length, cell) in m: below the region's low end, over that length, the cells grow
    only to ``cell`` (at least ``fine``) before they grow on to ``max_cell`` (e.g. a crater's
    path below the working region, in cells of a bounded height).
    """
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise MeshError(f"axis bounds must be finite with hi > lo, got ({lo}, {hi})")
    a, b = (float(region[0]), float(region[1]))
    if not (math.isfinite(a) and math.isfinite(b)) or a > b:
        raise MeshError(f"working region must be a finite interval (lo <= hi), got {region}")
    if b < lo or a > hi:
        raise MeshError(f"working region {region} lies outside the block's axis [{lo}, {hi}]")
    fine = _check_length("fine spacing", fine)
    if not (math.isfinite(growth) and 1.0 <= growth <= MAX_GROWTH):
        raise MeshError(f"growth ratio must lie in [1, {MAX_GROWTH}], got {growth!r}")
    if not (max_cell >= fine):
        raise MeshError(f"largest cell ({max_cell!r} m) must be at least the fine spacing {fine} m")
    if b - a < fine:
        a, b = 0.5 * (a + b) - 0.5 * fine, 0.5 * (a + b) + 0.5 * fine
    a, b = max(a, lo), min(b, hi)
    if a - lo < fine:
        a = lo
    if hi - b < fine:
        b = hi
    ratio = (b - a) / fine * (1.0 - 1e-12)  # inf for a subnormal fine spacing
    n_region = max(1, math.ceil(ratio)) if math.isfinite(ratio) else MAX_AXIS_NODES
    if n_region + 1 > MAX_AXIS_NODES:
        raise MeshError(
            f"a fine spacing of {fine} m over {b - a} m needs {n_region + 1} nodes on one axis "
            f"(at most {MAX_AXIS_NODES})"
        )
    h = (b - a) / n_region
    inner = np.full(n_region, h)
    if hi_cell is not None:
        hi_cell = _check_length("end cell", hi_cell)
        if hi_cell > fine:
            raise MeshError(f"end cell ({hi_cell} m) must not exceed the fine spacing {fine} m")
        if h > 0:  # else a collapsed region: the check below says so
            inner = refined_end(b - a, h, hi_cell, growth)
    # the cells outside grow from the region's (from its end cell above a refined end, and
    # below it from the fine one unless the refinement reaches the region's low side)
    low = float(inner[0]) if inner[0] * growth < h else h
    left = _lower_cells(a - lo, low, growth, max_cell, lo_tier)[::-1]
    right = _outer_cells(hi - b, float(inner[-1]), growth, max_cell)
    cells = np.concatenate([left, inner, right])
    if cells.size + 1 > MAX_AXIS_NODES:
        raise MeshError(f"graded axis needs {cells.size + 1} nodes (at most {MAX_AXIS_NODES})")
    x = lo + np.concatenate([[0.0], np.cumsum(cells)])
    x[-1] = hi
    if np.any(np.diff(x) <= 0.0):
        raise MeshError(f"graded axis on [{lo}, {hi}] collapsed a cell (fine spacing {fine} m)")
    return x
