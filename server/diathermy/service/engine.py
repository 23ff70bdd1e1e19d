"""The engine as the service sees it: build a simulation from a scene, load one from a checkpoint."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

from diathermy.scene import Scene


class EngineAdapter(Protocol):
    """Where simulations come from; the default is ``diathermy.engine.simulation.Simulation``."""

    def create(self, scene: Scene) -> Any: ...

    def load(self, path: Path) -> Any: ...


class DefaultEngine:
    """The real engine, imported on first use so that the app starts fast."""

    def create(self, scene: Scene) -> Any:
        from diathermy.engine.simulation import Simulation

        return Simulation(scene)

    def load(self, path: Path) -> Any:
        from diathermy.engine.simulation import Simulation

        return Simulation.load_checkpoint(path)
