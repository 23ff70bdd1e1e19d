"""Dependencies, declared once with ``Annotated`` aliases for the routes."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Path, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from diathermy.service.registry import SessionRecord
from diathermy.service.state import AppState
from diathermy.worker.queue import JobQueue

bearer = HTTPBearer(auto_error=False, description="a token the server was configured with")


def get_state(request: Request) -> AppState:
    return request.app.state.diathermy


StateDep = Annotated[AppState, Depends(get_state)]


def get_owner(
    state: StateDep,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)],
) -> str:
    """The caller's owner id (the sha256 of its token); 401 without a known token."""
    header = f"{credentials.scheme} {credentials.credentials}" if credentials else None
    return state.tokens.owner(header)


OwnerDep = Annotated[str, Depends(get_owner)]


def get_jobs(request: Request) -> JobQueue:
    """The job queue in the data directory (shared with the workers)."""
    return request.app.state.diathermy_jobs


JobsDep = Annotated[JobQueue, Depends(get_jobs)]


def get_session(
    state: StateDep,
    owner: OwnerDep,
    session_id: Annotated[str, Path(max_length=64, description="the session id")],
) -> SessionRecord:
    """The caller's session by id; 404 if it does not exist or belongs to another token."""
    return state.registry.get(owner, session_id)


SessionDep = Annotated[SessionRecord, Depends(get_session)]
