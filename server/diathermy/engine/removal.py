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
from diathermy.physics.topology import removed_fraction, removed_tets
from diathermy.physics.topology import tissue_share as share_of


def tissue_share(ctx: EngineContext, state: SimulationState) -> np.ndarray | None:
    """Each tet's tissue share (n_tets,) in [0, 1] under 'fraction' removal, from the last
    dissection's topology (from the level set and the removed mask when there is none, as
    after a restore: the removed tets that are not half cut are the loose ones); None under
    'threshold', or before anything is cut (the removed mask then says it all)."""
    if ctx.scene.level_set.removal != "fraction" or not ctx.has("dissection"):
        return None
    topology = state.memory.topology
    if topology is not None:
        return share_of(topology.fraction, topology.loose)
    removed = state["removed"]
    if not removed.any():
        return None
    fraction = removed_fraction(state["level_set"], ctx.disc.mesh.tets)
    return share_of(fraction, removed & ~removed_tets(fraction))
