"""Scene references as the command lines take them: a grid ``NZxNYxNX`` and a scene name or file."""

from __future__ import annotations

import argparse
from pathlib import Path

from diathermy.errors import SceneError
from diathermy.scene.builtin import builtin_scene, builtin_scene_names
from diathermy.scene.io import load_scene
from diathermy.scene.models import Scene


def parse_grid(text: str) -> tuple[int, int, int]:
    """``NZxNYxNX`` -> (nz, ny, nx)."""
    parts = text.lower().split("x")
    try:
        nz, ny, nx = (int(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"grid must look like 33x33x65 (nodes z, y, x), got {text!r}"
        ) from None
    if min(nz, ny, nx) < 3:
        raise argparse.ArgumentTypeError(f"every node count must be >= 3, got {text!r}")
    return nz, ny, nx


def resolve_scene(ref: str | None) -> Scene:
    """A built-in scene name, a path to a JSON/YAML scene file, or the default scene."""
    if ref is None:
        return builtin_scene("default")
    if ref in builtin_scene_names():
        return builtin_scene(ref)
    path = Path(ref)
    if path.suffix.lower() in {".json", ".yaml", ".yml"} or path.exists():
        return load_scene(path)
    raise SceneError(
        f"{ref!r} is neither a built-in scene ({', '.join(builtin_scene_names())}) nor a scene file"
    )
