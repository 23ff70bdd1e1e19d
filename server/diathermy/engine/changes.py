"""What a step (or one effect of it) changed: nodes per nodal field, tets per cell field, the tets
newly removed, and whether the electrode contact moved. Later work can be restricted to it."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from diathermy.engine.state import CELL_FIELDS

_EMPTY = np.zeros(0, dtype=np.int64)


@dataclass(frozen=True)
class ChangeSet:
    """Exact changes: index arrays (sorted, unique) of the entries whose value changed.

    nodes: nodal field name -> nodes whose value changed (a vector field: any component).
    tets: cell field name -> tets whose value changed.
    removed_tets: tets that became removed (the cut or a loose fragment grew).
    contact_moved: the contact disks of the electrodes differ from the previous step's.
    """

    nodes: dict[str, np.ndarray] = field(default_factory=dict)
    tets: dict[str, np.ndarray] = field(default_factory=dict)
    removed_tets: np.ndarray = field(default_factory=lambda: _EMPTY)
    contact_moved: bool = False

    @property
    def empty(self) -> bool:
        """True when nothing changed."""
        return not (self.nodes or self.tets or self.removed_tets.size or self.contact_moved)

    def changed_nodes(self, name: str) -> np.ndarray:
        """Nodes whose ``name`` changed (an empty array when none)."""
        return self.nodes.get(name, _EMPTY)

    def changed_tets(self, name: str) -> np.ndarray:
        """Tets whose ``name`` changed (an empty array when none)."""
        return self.tets.get(name, _EMPTY)

    def merge(self, other: ChangeSet) -> ChangeSet:
        """The union of two change sets (an entry changed by either)."""
        nodes = {k: np.union1d(self.changed_nodes(k), v) for k, v in other.nodes.items()}
        tets = {k: np.union1d(self.changed_tets(k), v) for k, v in other.tets.items()}
        return ChangeSet(
            nodes={**self.nodes, **nodes},
            tets={**self.tets, **tets},
            removed_tets=np.union1d(self.removed_tets, other.removed_tets),
            contact_moved=self.contact_moved or other.contact_moved,
        )


def changed_entries(old: np.ndarray, new: np.ndarray) -> np.ndarray:
    """Indices along the first axis where ``new`` differs from ``old`` (any component)."""
    diff = old != new
    if diff.ndim > 1:
        diff = diff.reshape(diff.shape[0], -1).any(axis=1)
    return np.flatnonzero(diff)


def field_changes(
    before: dict[str, np.ndarray], after: dict[str, np.ndarray], *, contact_moved: bool = False
) -> ChangeSet:
    """The change set from ``before`` to ``after`` over the fields ``after`` names."""
    nodes: dict[str, np.ndarray] = {}
    tets: dict[str, np.ndarray] = {}
    removed = _EMPTY
    for name, new in after.items():
        old = before[name]
        if old is new:
            continue
        idx = changed_entries(old, new)
        if idx.size == 0:
            continue
        (tets if name in CELL_FIELDS else nodes)[name] = idx
        if name == "removed":
            removed = idx[new[idx] & ~old[idx]]
    return ChangeSet(nodes=nodes, tets=tets, removed_tets=removed, contact_moved=contact_moved)


class PendingChanges:
    """A change set computed on first use from the arrays a step replaced: before (the arrays
    the fields held) and after (the arrays put in their place). Steps replace arrays and never
    write into them, so this stays exact while nobody writes into the state's arrays."""

    def __init__(
        self,
        before: dict[str, np.ndarray],
        after: dict[str, np.ndarray],
        *,
        contact_moved: bool = False,
    ) -> None:
        self.before, self.after, self.contact_moved = before, after, contact_moved
        self._resolved: ChangeSet | None = None

    def resolve(self) -> ChangeSet:
        """The change set (computed once)."""
        if self._resolved is None:
            self._resolved = field_changes(
                self.before, self.after, contact_moved=self.contact_moved
            )
            self.before, self.after = {}, {}  # let the replaced arrays go
        return self._resolved
