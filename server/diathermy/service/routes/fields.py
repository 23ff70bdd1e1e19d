"""Reading a session's state: fields (msgpack or npz), the cut surface, a VTU file."""

from __future__ import annotations

from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Query, Response

from diathermy.service import sessions as svc
from diathermy.service.deps import SessionDep, StateDep
from diathermy.service.encoding import encode_array, npz_bytes, pack
from diathermy.service.errors import ErrorResponses
from diathermy.service.schemas import FieldDtype, FieldFormat, SurfacePublic

router = APIRouter(prefix="/v1/sessions", tags=["fields"], responses=ErrorResponses)

FIELD_NAMES = (
    "potential",
    "temperature",
    "pressure",
    "vapor_fraction",
    "level_set",
    "thermal_damage",
    "displacement",
    "joule_heat",
    "strain_energy",
    "removed",
)
"""The fields every session has (``Simulation.field_names``); checked against it in a test."""

_BINARY: dict[int | str, dict[str, Any]] = {
    200: {
        "content": {
            "application/msgpack": {"schema": {"type": "string", "format": "binary"}},
            "application/x-npz": {"schema": {"type": "string", "format": "binary"}},
        },
        "description": "msgpack map {step, time_s, grid, fields: {name: {shape, dtype, data}}} "
        "or an .npz archive of the arrays plus 'step' and 'time_s'. Float fields come as "
        "``dtype``; 'removed' (per tetrahedron) is always bool ('|b1'), whatever ``dtype`` says",
    }
}


@router.get(
    "/{session_id}/fields", response_class=Response, responses=_BINARY, operation_id="read_fields"
)
async def read_fields(
    rec: SessionDep,
    state: StateDep,
    fields: Annotated[
        str,
        Query(
            max_length=1000,
            description="comma-separated names of " + ", ".join(FIELD_NAMES) + " (the stream's "
            "hello lists them too); an unknown name is a 400 naming the available ones",
        ),
    ],
    format: Annotated[FieldFormat, Query()] = "msgpack",
    dtype: Annotated[FieldDtype, Query()] = "float32",
) -> Response:
    """Nodal fields (nz, ny, nx[, 3]) and per-tet fields (n_tets,) of the current step."""
    step, time_s, arrays = await svc.read_fields(
        registry=state.registry, rec=rec, fields=fields, dtype=dtype
    )
    if format == "npz":
        extra = {"step": np.array(step), "time_s": np.array(time_s)}
        return Response(npz_bytes({**arrays, **extra}), media_type="application/x-npz")
    body = {
        "step": step,
        "time_s": time_s,
        "grid": rec.meta["grid"],
        "fields": {n: encode_array(a) for n, a in arrays.items()},
    }
    return Response(pack(body), media_type="application/msgpack")


@router.get(
    "/{session_id}/surface",
    operation_id="read_surface",
    response_model=SurfacePublic,
    responses={200: {"content": {"application/msgpack": {}}}},
)
async def read_surface(
    rec: SessionDep,
    state: StateDep,
    format: Annotated[str, Query(pattern="^(json|msgpack)$")] = "json",
) -> Any:
    """The cut surface as a triangle mesh: JSON lists, or msgpack arrays."""
    step, time_s, verts, faces = await svc.read_surface(registry=state.registry, rec=rec)
    if format == "msgpack":
        body = {
            "step": step,
            "time_s": time_s,
            "vertices_m": encode_array(verts),
            "faces": encode_array(faces.astype(np.int32)),
        }
        return Response(pack(body), media_type="application/msgpack")
    return SurfacePublic(step=step, time_s=time_s, vertices_m=verts.tolist(), faces=faces.tolist())


@router.get(
    "/{session_id}/vtu",
    operation_id="read_vtu",
    response_class=Response,
    responses={200: {"content": {"application/vnd.paraview.vtu": {}}}},
)
async def read_vtu(rec: SessionDep, state: StateDep) -> Response:
    """The current state as a ParaView .vtu file."""
    data = await svc.vtu_bytes(registry=state.registry, rec=rec)
    return Response(
        data,
        media_type="application/vnd.paraview.vtu",
        headers={"Content-Disposition": f'attachment; filename="{rec.id}.vtu"'},
    )
