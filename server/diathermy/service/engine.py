"""The engine as the service sees it: build a simulation from a scene, load one from a checkpoint.

The service resolves policy here and hands it to the engine: a scene's accuracy budget (the
accuracy report) and the model registry of its data directory.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Protocol

from diathermy.scene import Scene


class EngineAdapter(Protocol):
    """Where simulations come from; the default is ``diathermy.engine.simulation.Simulation``.

    It is pickled into each session's engine process and called there (``engine_ops.py``)."""

    def create(self, scene: Scene) -> Any: ...

    def load(self, path: Path) -> Any: ...


class DefaultEngine:
    """The real engine, imported on first use so that the app starts fast.

    ``data_dir``: the server's data directory, whose model registry resolves surrogate model
    names (None: model files and the shipped models only). ``DIATHERMY_ACCURACY_REPORT`` is read
    here, in the server, not in the engine processes (whose environment is the forkserver's)."""

    def __init__(self, data_dir: Path | None = None) -> None:
        self.data_dir = data_dir
        self.accuracy_report = os.environ.get("DIATHERMY_ACCURACY_REPORT")

    def _models(self) -> Any:
        if self.data_dir is None:
            return None
        from diathermy.worker.registry import RegistryModels

        return RegistryModels(self.data_dir)

    def create(self, scene: Scene) -> Any:
        from diathermy.engine.simulation import Simulation
        from diathermy.report.budget import resolve_accuracy_budget

        budgeted = resolve_accuracy_budget(scene, self.accuracy_report)
        return Simulation(budgeted, models=self._models())

    def load(self, path: Path) -> Any:
        from diathermy.engine.simulation import Simulation

        return Simulation.load_checkpoint(path, models=self._models())
