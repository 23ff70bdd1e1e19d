"""Limits checked before any allocation: grid size and its estimated memory, steps, sessions."""

from __future__ import annotations

from diathermy.service.config import Settings
from diathermy.service.exceptions import LimitExceededError, TooManySessionsError

BYTES_PER_NODE = 6_000
"""Fitted cost of one node with all effects (mesh, operators, AMG hierarchies, fields)."""
BASE_BYTES = 64 * 2**20
"""Fixed cost of a session independent of its grid."""


def estimate_memory_bytes(grid_shape: tuple[int, int, int]) -> int:
    """Estimated resident bytes of a session on this grid; the engine's own estimate if it has one."""
    try:
        from diathermy.engine.limits import estimate_memory_bytes as engine_estimate
    except ImportError:
        nz, ny, nx = grid_shape
        return BASE_BYTES + BYTES_PER_NODE * nz * ny * nx
    return int(engine_estimate(grid_shape))


def check_grid(settings: Settings, grid_shape: tuple[int, int, int]) -> int:
    """Reject a grid over the node or memory limit; returns its estimated bytes."""
    nz, ny, nx = grid_shape
    nodes = nz * ny * nx
    estimate = estimate_memory_bytes(grid_shape)
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
