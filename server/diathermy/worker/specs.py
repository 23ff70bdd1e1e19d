"""What a job asks for: a dataset (a ``DatagenConfig``) or a training run on a dataset job's output.

Torch-free on purpose: the service validates specs with these models without importing torch.
"""

from __future__ import annotations

from enum import Enum
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from diathermy.datagen.config import DatagenConfig
from diathermy.errors import SceneError

MODEL_NAME_PATTERN = r"^[a-z0-9][a-z0-9_-]{0,63}$"


class JobKind(str, Enum):  # noqa: UP042 (str() of members stays as before)
    dataset = "dataset"
    training = "training"


class JobState(str, Enum):  # noqa: UP042
    """A job's lifecycle: queued -> running -> succeeded | failed | cancelled."""

    queued = "queued"
    running = "running"
    succeeded = "succeeded"
    failed = "failed"
    cancelled = "cancelled"

    @property
    def terminal(self) -> bool:
        return self in (JobState.succeeded, JobState.failed, JobState.cancelled)


class JobSpecError(SceneError):
    """A job spec is invalid; the one-line message names the field."""


class _Spec(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class DatasetJobSpec(_Spec):
    """Generate the Algorithm 1 dataset of ``config`` (``diathermy datagen``), resumably."""

    model_config = ConfigDict(
        extra="forbid",
        frozen=True,
        json_schema_extra={
            "examples": [
                {"kind": "dataset", "config": {"grid": [5, 5, 9], "n_scenarios": 3, "n_steps": 2}}
            ]
        },
    )

    kind: Literal["dataset"] = "dataset"
    config: DatagenConfig
    engine: Literal["local", "dask"] = Field(
        "local", description="local processes, or an existing Dask cluster (needs 'scheduler')"
    )
    scheduler: str | None = Field(
        None, max_length=256, description="Dask scheduler address, e.g. tcp://10.0.0.5:8786"
    )
    workers: Annotated[int, Field(ge=1, le=256)] | None = Field(
        None, description="local scenario processes (default: config.workers)"
    )

    @model_validator(mode="after")
    def _scheduler_for_dask(self) -> DatasetJobSpec:
        if self.scheduler is not None and self.engine != "dask":
            raise ValueError("scheduler: only used with engine 'dask'")
        return self


class TrainOptions(_Spec):
    """The fields of ``surrogates.train_config.TrainConfig`` (mirrored here so no torch is needed)."""

    width: Annotated[int, Field(ge=1, le=256)] = 16
    depth: Annotated[int, Field(ge=1, le=32)] = 5
    epochs: Annotated[int, Field(ge=0, le=100_000)] = 50
    batch_size: Annotated[int, Field(ge=1, le=4096)] = 4
    lr: Annotated[float, Field(gt=0, le=10, allow_inf_nan=False)] = 1e-3
    val_fraction: Annotated[float, Field(gt=0, lt=1)] = 0.2
    patience: Annotated[int, Field(ge=1)] = 10
    seed: Annotated[int, Field(ge=0)] = 0
    amp: Literal["none", "bf16", "fp16"] = "none"
    device: Annotated[str, Field(max_length=32, pattern=r"^(auto|cpu|cuda(:\d+)?)$")] = "auto"
    num_workers: Annotated[int, Field(ge=0, le=64)] = 0
    scale_samples: Annotated[int, Field(ge=1)] = 256
    per_sample_amplitude: bool = True
    strain_weight: Annotated[float, Field(ge=0, le=1e3, allow_inf_nan=False)] = 1.0
    lr_schedule: Literal["constant", "cosine"] = "constant"
    energy_weight: Annotated[float, Field(ge=0, le=1e3, allow_inf_nan=False)] = 0.0
    mask_input: bool = False
    arch: Literal["pooled", "unet"] = "pooled"
    levels: Annotated[int, Field(ge=1, le=6)] = 4


class TrainingJobSpec(_Spec):
    """Train the CNN on a dataset job's output and register the model as ``model_name``."""

    model_config = ConfigDict(
        extra="forbid",
        frozen=True,
        json_schema_extra={
            "examples": [
                {
                    "kind": "training",
                    "dataset": "j-0123456789ab",
                    "model_name": "cnn",
                    "train": {"width": 4, "epochs": 2},
                }
            ]
        },
    )

    kind: Literal["training"] = "training"
    dataset: str = Field(
        min_length=1, max_length=64, description="id of a dataset job (it may still be running)"
    )
    model_name: str = Field("cnn", pattern=MODEL_NAME_PATTERN, description="registry name")
    train: TrainOptions = TrainOptions()
    activate: bool = Field(False, description="activate the new model for its grid when done")
    launcher: Literal["process", "torchrun"] = Field(
        "process", description="train in the worker's job process, or under torchrun (DDP)"
    )
    nproc_per_node: Annotated[int, Field(ge=1, le=64)] = Field(
        1, description="torchrun processes (launcher 'torchrun')"
    )

    @model_validator(mode="after")
    def _nproc_for_torchrun(self) -> TrainingJobSpec:
        if self.nproc_per_node != 1 and self.launcher != "torchrun":
            raise ValueError("nproc_per_node: only used with launcher 'torchrun'")
        return self


JobSpec = Annotated[DatasetJobSpec | TrainingJobSpec, Field(discriminator="kind")]


def _format_error(err: ValidationError) -> str:
    first = err.errors()[0]
    loc = ".".join(str(p) for p in first["loc"])
    msg = str(first["msg"]).removeprefix("Value error, ")
    if ": " in msg and msg.split(": ", 1)[0].replace(".", "").replace("_", "").isalnum():
        inner, msg = msg.split(": ", 1)
        loc = f"{loc}.{inner}" if loc else inner
    return f"{loc}: {msg}" if loc else msg


def spec_from_dict(data: Any) -> DatasetJobSpec | TrainingJobSpec:
    """Validate a job spec (``kind`` picks the model); ``JobSpecError`` names the field."""
    if not isinstance(data, dict):
        raise JobSpecError(f"a job spec must be a mapping, got {type(data).__name__}")
    kind = data.get("kind")
    model: type[DatasetJobSpec | TrainingJobSpec]
    if kind == JobKind.dataset.value:
        model = DatasetJobSpec
    elif kind == JobKind.training.value:
        model = TrainingJobSpec
    else:
        raise JobSpecError(f"kind: must be 'dataset' or 'training', got {kind!r}")
    try:
        return model.model_validate(data)
    except ValidationError as err:
        raise JobSpecError(_format_error(err)) from None
