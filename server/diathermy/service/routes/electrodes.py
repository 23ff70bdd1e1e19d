"""Reading a session's electrodes (position, drive, on/off) at its current time."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Path

from diathermy.service.deps import SessionDep, StateDep
from diathermy.service.electrodes import ElectrodeList, ElectrodeState, read_electrodes
from diathermy.service.errors import ErrorResponses

router = APIRouter(prefix="/v1/sessions", tags=["sessions"], responses=ErrorResponses)


@router.get(
    "/{session_id}/electrodes", response_model=ElectrodeList, operation_id="list_electrodes"
)
async def list_electrodes(rec: SessionDep, state: StateDep) -> Any:
    """Every electrode: position (m), radius, drive, power or current density, on/off, now."""
    return ElectrodeList(electrodes=await read_electrodes(registry=state.registry, rec=rec))


@router.get(
    "/{session_id}/electrodes/{name}",
    response_model=ElectrodeState,
    operation_id="get_electrode",
)
async def get_electrode(
    rec: SessionDep, state: StateDep, name: Annotated[str, Path(max_length=128)]
) -> Any:
    """One electrode by name (404 naming ``name`` if the scene has none by that name)."""
    (one,) = await read_electrodes(registry=state.registry, rec=rec, name=name)
    return one
