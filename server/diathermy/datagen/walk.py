"""Algorithm 1's random walk over tetrahedra: start tets, face-neighbour steps, pressure draws.

Randomness is Python's Mersenne Twister (``random.Random``) seeded by a string key, so every
scenario can be regenerated alone from (base seed, scenario index), on any machine or worker.

Rules (documented choices):
- Start: scenario ``i`` starts at entry ``i`` of one shuffle of the top-surface tets (a face on
  ``z+``) drawn from the base seed alone, so no two scenarios share a start and adding scenarios
  keeps the earlier ones.
- Step: the walk moves to a uniformly drawn unvisited healthy face-neighbour of the last visited
  tet. Stuck (none): it backtracks to the most recent visited tet that has one and moves from
  there; if no visited tet has one, the step adds no tet and only perturbs.
- Pressures: a newly visited tet draws p ~ U[p_min, p_max]; each earlier visited tet is then
  scaled by (1 + U[-f, f]) and clamped to [p_min, p_max] (f = 0.05 by default).
- Draw order per step: the neighbour, the new pressure, then perturbations in visit order.
"""

from __future__ import annotations

import random
from dataclasses import dataclass

import numpy as np

from diathermy.mesh import TetMesh

_KEY = "diathermy-datagen"


def scenario_rng(seed: int, index: int) -> random.Random:
    """The Mersenne Twister of scenario ``index`` under base ``seed``."""
    return random.Random(f"{_KEY}:{seed}:scenario:{index}")


def legacy_numpy_seed(seed: int, index: int) -> int:
    """A 32-bit seed for numpy's global RNG in scenario ``index`` (see ``run_scenario``)."""
    return random.Random(f"{_KEY}:{seed}:numpy:{index}").getrandbits(32)


def surface_tets(mesh: TetMesh) -> np.ndarray:
    """Sorted indices of the tets with a face on the top side ``z+``."""
    k, _, _ = mesh.grid.grid_index(mesh.tets)
    return np.flatnonzero((k == mesh.grid.nz - 1).sum(axis=1) == 3)


def start_tets(surface: np.ndarray, seed: int, n: int) -> np.ndarray:
    """The start tets (n,) of scenarios 0..n-1: a prefix of one seeded shuffle of ``surface``."""
    order = [int(t) for t in surface]
    random.Random(f"{_KEY}:{seed}:starts").shuffle(order)
    if n > len(order):
        raise ValueError(f"{n} scenarios need distinct start tets, only {len(order)} exist")
    return np.asarray(order[:n], dtype=np.int64)


@dataclass(frozen=True)
class Move:
    """One walk step: the tet newly visited and the visited tet it came from (-1: none)."""

    tet: int
    parent: int


def next_move(
    visited: list[int],
    visited_set: set[int],
    neighbours: np.ndarray,
    healthy: np.ndarray,
    rng: random.Random,
) -> Move:
    """The next tet by the walk's step and stuck rules; ``Move(-1, -1)`` when nothing is left.

    ``neighbours`` (n_tets, 4) face neighbours (-1 on the boundary), ``healthy`` (n_tets,) bool.
    """
    for parent in reversed(visited):
        cand = sorted(
            {int(t) for t in neighbours[parent] if t >= 0 and healthy[t] and t not in visited_set}
        )
        if cand:
            return Move(cand[rng.randrange(len(cand))], parent)
    return Move(-1, -1)


def draw_pressure(rng: random.Random, p_min: float, p_max: float) -> float:
    """A fresh tet pressure ~ U[p_min, p_max] in Pa."""
    return p_min + (p_max - p_min) * rng.random()


def perturb(
    p: np.ndarray, rng: random.Random, fraction: float, p_min: float, p_max: float
) -> np.ndarray:
    """New pressures (n,): each p_i * (1 + U[-fraction, fraction]) clamped to [p_min, p_max]."""
    factors = np.array([1.0 + fraction * (2.0 * rng.random() - 1.0) for _ in range(p.size)])
    return np.clip(p * factors, p_min, p_max)
