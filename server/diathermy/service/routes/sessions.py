"""Sessions: create, list, inspect, step, drive electrodes, snapshot, restore, delete."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Path, Response

from diathermy.service import sessions as svc
from diathermy.service.deps import OwnerDep, SessionDep, StateDep
from diathermy.service.errors import ErrorResponses
from diathermy.service.hub import finite
from diathermy.service.schemas import (
    ElectrodeAck,
    ElectrodeUpdate,
    SessionCreate,
    SessionList,
    SessionPublic,
    SnapshotPublic,
    StepRequest,
    StepResult,
)

SESSION_LINKS = {
    op: {"operationId": op, "parameters": {"session_id": "$response.body#/id"}}
    for op in (
        "get_session",
        "list_electrodes",
        "step_session",
        "take_snapshot",
        "list_snapshots",
        "read_fields",
        "read_surface",
        "read_vtu",
        "delete_session",
    )
}
"""OpenAPI links from a created session to what can be done with it (used by fuzzers)."""

router = APIRouter(prefix="/v1/sessions", tags=["sessions"], responses=ErrorResponses)


@router.post(
    "",
    status_code=201,
    response_model=SessionPublic,
    operation_id="create_session",
    responses={201: {"links": SESSION_LINKS}},
)
async def create_session(body: SessionCreate, state: StateDep, owner: OwnerDep) -> Any:
    """Build a simulation from a scene (inline or built-in); 201 with its grid, effects, DOFs."""
    rec = await svc.create_session(
        registry=state.registry,
        settings=state.settings,
        metrics=state.metrics,
        owner=owner,
        body=body,
    )
    return svc.session_public(rec)


@router.get("", response_model=SessionList, operation_id="list_sessions")
async def list_sessions(state: StateDep, owner: OwnerDep) -> Any:
    """The caller's sessions."""
    return SessionList(sessions=[svc.session_public(r) for r in state.registry.owned(owner)])


@router.get("/{session_id}", response_model=SessionPublic, operation_id="get_session")
async def get_session(rec: SessionDep) -> Any:
    """One session: step, time, grid, the last step report."""
    return svc.session_public(rec)


@router.delete("/{session_id}", status_code=204, operation_id="delete_session")
async def delete_session(rec: SessionDep, state: StateDep) -> Response:
    """Stop and delete a session and its files."""
    await svc.delete_session(registry=state.registry, rec=rec)
    return Response(status_code=204)


@router.post("/{session_id}/step", response_model=StepResult, operation_id="step_session")
async def step_session(rec: SessionDep, state: StateDep, body: StepRequest | None = None) -> Any:
    """Take n steps (409 if the session is already stepping); returns their reports."""
    n = body.n if body is not None else 1
    reports = await svc.step_session(
        registry=state.registry, settings=state.settings, metrics=state.metrics, rec=rec, n=n
    )
    return StepResult(
        step=int(reports[-1].step),  # n >= 1: the state after the last step taken
        time_s=float(reports[-1].time_s),
        reports=[finite(r.to_dict()) for r in reports],
    )


@router.patch(
    "/{session_id}/electrodes/{name}", response_model=ElectrodeAck, operation_id="update_electrode"
)
async def update_electrode(
    rec: SessionDep,
    state: StateDep,
    name: Annotated[str, Path(max_length=128)],
    body: ElectrodeUpdate,
) -> Any:
    """Move, re-power or switch an electrode; applies from the next step."""
    control_id, _ = await svc.update_electrode(
        registry=state.registry, rec=rec, name=name, update=body
    )
    return ElectrodeAck(name=name, control_id=control_id)


@router.post(
    "/{session_id}/snapshots",
    status_code=201,
    response_model=SnapshotPublic,
    operation_id="take_snapshot",
)
async def take_snapshot(rec: SessionDep, state: StateDep) -> Any:
    """Save the current state under a new snapshot id."""
    return await svc.take_snapshot(registry=state.registry, rec=rec)


@router.get(
    "/{session_id}/snapshots", response_model=list[SnapshotPublic], operation_id="list_snapshots"
)
async def list_snapshots(rec: SessionDep) -> Any:
    """The session's snapshots, oldest first."""
    return [SnapshotPublic(**s) for s in rec.meta.get("snapshots", [])]


@router.post(
    "/{session_id}/snapshots/{snapshot_id}/restore",
    response_model=SessionPublic,
    operation_id="restore_snapshot",
)
async def restore_snapshot(
    rec: SessionDep,
    state: StateDep,
    snapshot_id: Annotated[str, Path(max_length=64)],
) -> Any:
    """Put the session back to a snapshot (409 while it is stepping)."""
    await svc.restore_snapshot(registry=state.registry, rec=rec, snapshot_id=snapshot_id)
    return svc.session_public(rec)
