"""Scenes: what to simulate (block, grid, tissue, electrodes, effects, solvers), as versioned models."""

from diathermy.scene.builtin import builtin_scene, builtin_scene_names
from diathermy.scene.io import load_scene, scene_from_dict, scene_json_schema
from diathermy.scene.models import (
    EFFECTS,
    AccuracyBudget,
    Electrode,
    ElectrodePath,
    LevelSetConfig,
    MechanicsConfig,
    Scene,
    SolverConfig,
    close_effects,
)
from diathermy.scene.resolution import Resolution
from diathermy.scene.resolve import parse_grid, resolve_scene

__all__ = [
    "EFFECTS",
    "AccuracyBudget",
    "Electrode",
    "ElectrodePath",
    "LevelSetConfig",
    "MechanicsConfig",
    "Resolution",
    "Scene",
    "SolverConfig",
    "builtin_scene",
    "builtin_scene_names",
    "close_effects",
    "load_scene",
    "parse_grid",
    "resolve_scene",
    "scene_from_dict",
    "scene_json_schema",
]
