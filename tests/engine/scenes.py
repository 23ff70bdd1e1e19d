"""Small scenes that vaporise and cut within a few dozen steps, for engine tests."""

from __future__ import annotations

from typing import Any

from diathermy.scene import Electrode, Scene


def tiny_scene(**overrides: Any) -> Scene:
    """A 2 x 1 x 1 cm block on a 9x9x17 grid, 30 W at the top centre: boils by step ~5, cuts by ~15."""
    base: dict[str, Any] = dict(
        name="tiny",
        grid=(9, 9, 17),
        block_m=(0.02, 0.01, 0.01),
        electrodes=[Electrode(position_m=(0.01, 0.005), power_w=30.0)],
        steps=40,
    )
    base.update(overrides)
    return Scene(**base)
