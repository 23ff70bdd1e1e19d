"""Training data for the mechanics surrogates by Algorithm 1: random pressure walks, FEM, HDF5."""

from diathermy.datagen.config import (
    DatagenConfig,
    DatagenConfigError,
    config_from_dict,
    load_config,
)
from diathermy.datagen.generate import GenerateSummary, generate
from diathermy.datagen.reader import DatasetReader
from diathermy.datagen.scenario import PhysicsFactory, Sample, ScenarioPhysics, run_scenario
from diathermy.datagen.storage import DatasetWriter

__all__ = [
    "DatagenConfig",
    "DatagenConfigError",
    "DatasetReader",
    "DatasetWriter",
    "GenerateSummary",
    "PhysicsFactory",
    "Sample",
    "ScenarioPhysics",
    "config_from_dict",
    "generate",
    "load_config",
    "run_scenario",
]
