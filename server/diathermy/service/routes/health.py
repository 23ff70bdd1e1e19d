"""Liveness, readiness and Prometheus metrics (no auth: they reveal no session data)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Response
from fastapi.responses import JSONResponse
from prometheus_client import CONTENT_TYPE_LATEST

from diathermy.service.deps import StateDep
from diathermy.service.schemas import Health

router = APIRouter(tags=["health"])


@router.get("/healthz", response_model=Health)
async def healthz() -> Any:
    """The process is up."""
    return Health(status="ok")


@router.get("/readyz", response_model=Health, responses={503: {"model": Health}})
async def readyz(state: StateDep) -> Any:
    """The server has scanned its data directory and takes requests (503 until then)."""
    if not state.ready:
        return JSONResponse(Health(status="starting").model_dump(), status_code=503)
    return Health(status="ok", sessions=len(state.registry.sessions))


@router.get(
    "/metrics",
    response_class=Response,
    responses={200: {"content": {"text/plain": {}}}},
)
async def metrics(state: StateDep) -> Response:
    """Prometheus exposition: step times per effect, sessions, stream frames sent and dropped."""
    return Response(state.metrics.exposition(), media_type=CONTENT_TYPE_LATEST)
