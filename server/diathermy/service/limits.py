"""Limits checked before any allocation: grid size and its estimated memory, steps, sessions,
and the physical range of an electrode's drive."""

from __future__ import annotations

from collections.abc import Iterable

from diathermy.engine.limits import estimate_memory_bytes
from diathermy.scene import Scene
from diathermy.service.config import Settings
from diathermy.service.exceptions import LimitExceededError, TooManySessionsError

MAX_POWER_W = 1000.0
"""Highest electrode power accepted, W: electrosurgical generators deliver up to ~400 W."""

MAX_CURRENT_DENSITY_A_PER_M2 = 1.0e7
"""Highest electrode current density accepted, A/m^2 (the default scene drives 5.72e4)."""


MAX_VOLTAGE_V = 1.0e4
"""Highest generator voltage limit accepted, V (electrosurgical outputs reach a few kV peak)."""


def check_drive(scene: Scene) -> None:
    """Reject a scene whose electrodes are driven beyond the physical range (422 naming it)."""
    for i, el in enumerate(scene.electrodes):
        for name, value, top in (
            ("power_w", el.power_w, MAX_POWER_W),
            ("current_density_a_per_m2", el.current_density_a_per_m2, MAX_CURRENT_DENSITY_A_PER_M2),
            ("max_voltage_v", el.max_voltage_v or 0.0, MAX_VOLTAGE_V),
        ):
            if value > top:
                raise LimitExceededError(
                    f"{name} {value:g} is over the limit of {top:g}",
                    field=f"scene.electrodes.{i}.{name}",
                )


def check_grid(settings: Settings, grid_shape: tuple[int, int, int], effects: Iterable[str]) -> int:
    """Reject a grid over the node or memory limit (the engine's estimate); returns the bytes."""
    nz, ny, nx = grid_shape
    nodes = nz * ny * nx
    estimate = estimate_memory_bytes(grid_shape, effects)
    mib = estimate / 2**20
    if nodes > settings.max_grid_nodes:
        raise LimitExceededError(
            f"grid {nz}x{ny}x{nx} has {nodes} nodes, over the limit of "
            f"{settings.max_grid_nodes} (estimated memory {mib:.0f} MiB)",
            field="scene.grid",
        )
    if estimate > settings.max_memory_bytes:
        raise LimitExceededError(
            f"grid {nz}x{ny}x{nx} needs an estimated {mib:.0f} MiB, over the limit of "
            f"{settings.max_memory_bytes / 2**20:.0f} MiB",
            field="scene.grid",
        )
    return estimate


def check_steps(settings: Settings, n: int) -> None:
    """Reject more steps per request than allowed."""
    if n > settings.max_steps_per_request:
        raise LimitExceededError(
            f"{n} steps per request is over the limit of {settings.max_steps_per_request}",
            field="n",
        )


def check_session_count(settings: Settings, owned: int) -> None:
    """Reject a new session when the owner already has the maximum."""
    if owned >= settings.max_sessions_per_token:
        raise TooManySessionsError(
            f"this token already owns {owned} sessions, the limit is "
            f"{settings.max_sessions_per_token}; delete one first",
        )
