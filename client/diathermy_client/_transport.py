"""Turning httpx answers and failures into the SDK's terms (shared by both clients)."""

from __future__ import annotations

import httpx

from diathermy_client._core import Request, Response
from diathermy_client._errors import DiathermyError, Timeout, TransportError


def to_response(r: httpx.Response) -> Response:
    return Response(r.status_code, r.content, r.headers.get("content-type", ""))


def transport_error(req: Request, err: httpx.HTTPError) -> DiathermyError:
    what = f"{req.method} {req.path}"
    if isinstance(err, httpx.TimeoutException):
        return Timeout(f"{what}: no answer in time ({type(err).__name__})")
    return TransportError(f"{what}: {type(err).__name__}: {err}")
