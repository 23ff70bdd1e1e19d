"""How much memory a simulation needs, estimated before anything is allocated.

Fitted to peak RSS of build + first steps (benchmarks/engine_memory.py, results in
benchmarks/results/engine_memory.md): a fixed cost plus a cost per node that depends on whether
the mechanics (a 3-DOF-per-node elastic operator and its AMG hierarchy) is part of the scene.
"""

from __future__ import annotations

from collections.abc import Iterable

from diathermy.scene.models import close_effects

BASE_BYTES = 16 * 2**20
"""Fixed cost of a simulation independent of its grid (fitted: 4-16 MiB)."""
BYTES_PER_NODE = 7_500
"""Mesh, geometry, fields and the scalar (electric, thermal) operators and hierarchies
(fitted: 6.9 kB per node on 9x9x17 .. 33x33x65, rounded up)."""
MECHANICS_BYTES_PER_NODE = 9_000
"""Added by mechanics (and the vaporization and dissection it comes with): the 3x3-block elastic
operator, its AMG hierarchy, strain energy, the level set (fitted: 16.0 kB per node in all)."""


def estimate_memory_bytes(grid_shape: tuple[int, int, int], effects: Iterable[str]) -> int:
    """Estimated peak resident bytes of one simulation of ``effects`` on nodes (nz, ny, nx)."""
    nz, ny, nx = grid_shape
    nodes = nz * ny * nx
    per_node = BYTES_PER_NODE
    if "mechanics" in close_effects(tuple(effects)):
        per_node += MECHANICS_BYTES_PER_NODE
    return BASE_BYTES + per_node * nodes
