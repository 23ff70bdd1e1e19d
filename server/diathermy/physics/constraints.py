"""Dirichlet constraints of the elastic solve: prescribed displacement components per DOF."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diathermy.errors import SceneError
from diathermy.mesh import TetMesh


@dataclass(frozen=True)
class Constraints:
    """Prescribed displacement components: DOF ``3 * node + i`` held at ``values`` (m)."""

    dofs: np.ndarray
    values: np.ndarray

    def __post_init__(self) -> None:
        dofs = np.asarray(self.dofs, dtype=np.int64).ravel()
        values = np.broadcast_to(np.asarray(self.values, dtype=float), dofs.shape)
        if not np.all(np.isfinite(values)):
            raise SceneError("constraint values must be finite")
        dofs, first = np.unique(dofs, return_index=True)  # later duplicates are dropped
        object.__setattr__(self, "dofs", dofs)
        object.__setattr__(self, "values", np.ascontiguousarray(values[first]))

    @classmethod
    def on_nodes(
        cls, nodes: np.ndarray, components: tuple[int, ...] = (0, 1, 2), value_m: float = 0.0
    ) -> Constraints:
        """Hold the given components (0 x, 1 y, 2 z) of ``nodes`` at ``value_m``."""
        comps = np.asarray(components, dtype=np.int64)
        dofs = 3 * np.asarray(nodes, dtype=np.int64)[:, None] + comps[None, :]
        return cls(dofs.ravel(), np.full(dofs.size, value_m))

    def __add__(self, other: Constraints) -> Constraints:
        return Constraints(
            np.concatenate([self.dofs, other.dofs]), np.concatenate([self.values, other.values])
        )

    def mask(self, n_dofs: int) -> np.ndarray:
        """Boolean (n_dofs,) of the constrained DOFs."""
        if self.dofs.size and (self.dofs[0] < 0 or self.dofs[-1] >= n_dofs):
            raise SceneError(f"constrained DOFs must lie in [0, {n_dofs})")
        out = np.zeros(n_dofs, dtype=bool)
        out[self.dofs] = True
        return out


def clamped_bottom(mesh: TetMesh) -> Constraints:
    """u = 0 on the bottom z- (the tissue lies on the dispersive electrode)."""
    return Constraints.on_nodes(mesh.side_nodes("z-"))


def rollers(mesh: TetMesh, sides: tuple[str, ...]) -> Constraints:
    """Zero normal displacement on each named side (``x-``, ``y+``, ...); tangential free."""
    out = Constraints(np.zeros(0, dtype=np.int64), np.zeros(0))
    for side in sides:
        out = out + Constraints.on_nodes(mesh.side_nodes(side), ("xyz".index(side[0]),))
    return out
