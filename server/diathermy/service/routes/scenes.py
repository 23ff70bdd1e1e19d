"""The built-in scenes a session can start from."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from diathermy.scene import Scene, builtin_scene, builtin_scene_names

router = APIRouter(prefix="/v1/scenes", tags=["scenes"])


@router.get("", response_model=dict[str, Scene])
async def list_scenes() -> Any:
    """Every built-in scene by name, with all defaults filled in."""
    return {name: builtin_scene(name) for name in builtin_scene_names()}
