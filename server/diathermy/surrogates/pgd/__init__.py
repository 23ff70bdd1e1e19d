"""Hybrid-PGD: a proper-generalized-decomposition reduced model of the mechanics (numpy/scipy/sklearn).

u(x; s, p, g) ~= sum_i M_i(x) N_i(s) R_i(p) S_i(g): s the electrode position (x, y) on the top
surface, p = (Q, r) the overpressure's strength and radius, g the topology's kernel-PCA
coordinates. ``parameters`` maps a state to (s, Q, r, g), ``kpca`` the level set to g,
``offline`` builds the modes by greedy rank-one enrichment from FEM snapshots, ``model`` stores
and evaluates them, ``online`` adds modes where an error indicator says the state left the
training manifold, ``backend`` plugs the model into the engine. No torch here. Names load
lazily, so the CLI parser does not import scikit-learn.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "PGDModel": "diathermy.surrogates.pgd.model",
    "load_model": "diathermy.surrogates.pgd.model",
    "save_model": "diathermy.surrogates.pgd.model",
    "TrainingManifold": "diathermy.surrogates.pgd.offline",
    "build_model": "diathermy.surrogates.pgd.offline",
    "rank_one_enrichment": "diathermy.surrogates.pgd.offline",
    "PGDBackend": "diathermy.surrogates.pgd.backend",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module 'diathermy.surrogates.pgd' has no attribute {name!r}")
    return getattr(importlib.import_module(_EXPORTS[name]), name)


def __dir__() -> list[str]:
    return __all__
