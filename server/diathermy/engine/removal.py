"""How the cut enters the material properties: the scene's ``level_set.removal``.

'threshold': a tet is removed tissue once half its volume is cut (the ``removed`` mask); each
effect switches its property there. 'fraction': each tet's properties blend the tissue's and the
removed tissue's by the share still tissue (``physics.topology.tissue_share``), so conductivity,
heat conduction, stiffness, pore pressure and the cut's driver are continuous in the level set.
"""

from __future__ import annotations

import numpy as np

from diathermy.engine.context import EngineContext
from diathermy.engine.state import SimulationState
from diathermy.physics.topology import tissue_share as topology_share


def tissue_share(ctx: EngineContext, state: SimulationState) -> np.ndarray | None:
    """Each tet's tissue share (n_tets,) in [0, 1] under 'fraction' removal, from the last
    dissection's topology; None under 'threshold', or before anything is cut (the removed mask
    then says it all)."""
    if ctx.scene.level_set.removal != "fraction" or not ctx.has("dissection"):
        return None
    topology = state.memory.topology
    if topology is None:
        removed = state["removed"]
        return (~removed).astype(float) if removed.any() else None
    return topology_share(topology)
