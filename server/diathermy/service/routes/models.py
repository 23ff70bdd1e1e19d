"""Models: the registry of trained surrogates; list, inspect, activate one for its grid."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Path

from diathermy.service import jobs as svc
from diathermy.service.deps import OwnerDep, StateDep
from diathermy.service.errors import ErrorResponses
from diathermy.service.job_schemas import ModelList, ModelPublic

router = APIRouter(prefix="/v1/models", tags=["models"], responses=ErrorResponses)
Name = Annotated[str, Path(max_length=64, description="the model name")]
Version = Annotated[int, Path(ge=1, le=2**31, description="the model version")]


@router.get("", response_model=ModelList, operation_id="list_models")
def list_models(state: StateDep, _owner: OwnerDep) -> Any:
    """Every registered model and which is active per grid."""
    return svc.list_registered(data_dir=state.settings.data_dir)


@router.get("/{name}/{version}", response_model=ModelPublic, operation_id="get_model")
def get_model(name: Name, version: Version, state: StateDep, _owner: OwnerDep) -> Any:
    """One model: grid, architecture, dataset hash, evaluation metrics."""
    return svc.get_registered(data_dir=state.settings.data_dir, name=name, version=version)


@router.post(
    "/{name}/{version}/activate", response_model=ModelPublic, operation_id="activate_model"
)
def activate_model(name: Name, version: Version, state: StateDep, _owner: OwnerDep) -> Any:
    """Make this model the one new CNN sessions on its grid use (unless a scene names one)."""
    return svc.activate_registered(data_dir=state.settings.data_dir, name=name, version=version)
