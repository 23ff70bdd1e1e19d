"""The training worker: a job queue (SQLite), job processes, and the model registry."""

from diathermy.worker.job_records import Job, JobProgress
from diathermy.worker.queue import JobNotFoundError, JobQueue
from diathermy.worker.registry import (
    ModelInfo,
    ModelNotFoundError,
    activate_model,
    active_models,
    get_model,
    list_models,
    register_model,
    resolve_model,
)
from diathermy.worker.specs import (
    DatasetJobSpec,
    JobKind,
    JobSpecError,
    JobState,
    TrainingJobSpec,
    TrainOptions,
    spec_from_dict,
)

__all__ = [
    "DatasetJobSpec",
    "Job",
    "JobKind",
    "JobNotFoundError",
    "JobProgress",
    "JobQueue",
    "JobSpecError",
    "JobState",
    "ModelInfo",
    "ModelNotFoundError",
    "TrainOptions",
    "TrainingJobSpec",
    "activate_model",
    "active_models",
    "get_model",
    "list_models",
    "register_model",
    "resolve_model",
    "spec_from_dict",
]
