"""Loading scenes from JSON or YAML files, with one-line errors that name the offending field."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from diathermy.errors import SceneError
from diathermy.scene.models import Scene


def describe_validation_error(err: ValidationError, prefix: str = "") -> str:
    """One line per problem: ``field.path: message``."""
    lines = []
    for e in err.errors():
        loc = ".".join(str(p) for p in e["loc"])
        msg = str(e["msg"]).removeprefix("Value error, ")
        lines.append(f"{prefix}{loc}: {msg}" if loc else f"{prefix}{msg}")
    return "; ".join(lines)


def scene_from_dict(data: Any) -> Scene:
    """Validate a parsed scene document; raises ``SceneError`` naming the field."""
    if not isinstance(data, dict):
        raise SceneError(f"a scene must be a mapping of fields, got {type(data).__name__}")
    try:
        return Scene.model_validate(data)
    except ValidationError as err:
        raise SceneError(describe_validation_error(err)) from None


def load_scene(path: str | Path) -> Scene:
    """Read a scene from a .json, .yaml or .yml file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise SceneError(f"cannot read scene file {path}: {err.strerror or err}") from None
    except UnicodeDecodeError:
        raise SceneError(f"scene file {path} is not UTF-8 text") from None
    try:
        if path.suffix.lower() in {".yaml", ".yml"}:
            data = yaml.safe_load(text)
        else:
            data = json.loads(text)
    except (json.JSONDecodeError, yaml.YAMLError) as err:
        first = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise SceneError(
            f"scene file {path} is not valid {path.suffix[1:] or 'JSON'}: {first}"
        ) from None
    return scene_from_dict(data)


def scene_json_schema() -> dict[str, Any]:
    """The JSON Schema of the scene model."""
    schema = Scene.model_json_schema()
    schema["$id"] = "https://diathermy.dev/schema/scene-v1.json"
    return schema
