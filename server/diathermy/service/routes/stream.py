"""The WebSocket stream of a session (wire format: docs/service.md, openapi/stream-messages.json)."""

from __future__ import annotations

from fastapi import APIRouter, WebSocket

from diathermy.service.stream import serve_stream

router = APIRouter(prefix="/v1/sessions", tags=["stream"])


@router.websocket("/{session_id}/stream")
async def stream(websocket: WebSocket, session_id: str) -> None:
    """Subscribe to frames and drive the session; see docs/service.md for the messages."""
    await serve_stream(websocket, websocket.app.state.diathermy, session_id)
