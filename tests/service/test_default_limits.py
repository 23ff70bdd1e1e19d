"""The service's default limits admit every built-in scene and still refuse what is past them."""

from __future__ import annotations

import pytest

from diathermy.engine.limits import estimate_memory_bytes
from diathermy.scene import builtin_scene, builtin_scene_names
from diathermy.service.config import Settings
from diathermy.service.exceptions import LimitExceededError
from diathermy.service.limits import check_grid


@pytest.fixture
def defaults(monkeypatch: pytest.MonkeyPatch) -> Settings:
    for var in ("DIATHERMY_MAX_GRID_NODES", "DIATHERMY_MAX_MEMORY_BYTES"):
        monkeypatch.delenv(var, raising=False)
    return Settings()


@pytest.mark.parametrize("name", builtin_scene_names())
def test_a_default_server_accepts_every_builtin_scene(defaults: Settings, name: str) -> None:
    """A client that asks a default ``diathermy serve`` for a built-in scene gets a session (the
    viewer offers them all): the fixed electrode's 446 k nodes and ~7 GiB were refused by the
    300000-node, 4 GiB defaults before 2026-12-07, the moving electrodes' 4.4 GiB too."""
    scene = builtin_scene(name)
    assert check_grid(defaults, scene.node_shape, scene.effects) == estimate_memory_bytes(
        scene.node_shape, scene.effects
    )


def test_a_default_server_still_refuses_a_grid_past_its_limits(defaults: Settings) -> None:
    """Past the node limit (for every effect the node limit binds before the memory one: ~16 kB a
    node) a session is refused before anything is allocated, naming the field."""
    effects = builtin_scene("default").effects
    with pytest.raises(LimitExceededError, match="over the limit of 500000") as refused:
        check_grid(defaults, (81, 81, 81), effects)  # 531 k nodes, ~8.3 GiB
    assert refused.value.field == "scene.grid"
    assert estimate_memory_bytes((81, 81, 81), effects) > defaults.max_memory_bytes
