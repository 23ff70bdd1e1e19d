"""The one place where errors become HTTP responses: ``{"error", "message", "field"}`` JSON."""

from __future__ import annotations

import logging
import re

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

from diathermy.errors import (
    CheckpointError,
    DiathermyError,
    MeshError,
    SceneError,
    SolverDivergedError,
)
from diathermy.service.exceptions import (
    AuthError,
    BadRequestError,
    EngineProcessError,
    LimitExceededError,
    NotFoundError,
    RequestTooLargeError,
    ServiceError,
    SessionBusyError,
    SessionNotFoundError,
    TooManyJobsError,
    TooManySessionsError,
)
from diathermy.service.schemas import ErrorPublic

log = logging.getLogger("diathermy.service.errors")

STATUS: list[tuple[type[Exception], int, str]] = [
    (AuthError, 401, "unauthorized"),
    (SessionNotFoundError, 404, "not_found"),
    (NotFoundError, 404, "not_found"),
    (SessionBusyError, 409, "busy"),
    (TooManySessionsError, 429, "too_many_sessions"),
    (TooManyJobsError, 429, "too_many_jobs"),
    (RequestTooLargeError, 413, "too_large"),
    (LimitExceededError, 422, "limit_exceeded"),
    (BadRequestError, 400, "bad_request"),
    (SceneError, 422, "scene_error"),
    (MeshError, 422, "mesh_error"),
    (SolverDivergedError, 422, "solver_diverged"),
    (CheckpointError, 409, "checkpoint_error"),
    (EngineProcessError, 503, "engine_failed"),
    (DiathermyError, 400, "error"),
]
"""Exception class -> (HTTP status, error code); the first match wins, so subclasses come first."""

_FIELD = re.compile(r"^([A-Za-z_][\w.\[\]]*): ")


def classify(err: Exception) -> tuple[int, str, str | None]:
    """(status, code, field) of an error; the field from ``ServiceError.field`` or 'path: ...'."""
    for cls, status, code in STATUS:
        if isinstance(err, cls):
            field = err.field if isinstance(err, ServiceError) else None
            if field is None:
                m = _FIELD.match(str(err))
                field = m.group(1) if m else None
            return status, code, field
    return 500, "internal", None


def error_body(code: str, message: str, field: str | None = None) -> dict[str, str | None]:
    return {"error": code, "message": message, "field": field}


async def _diathermy_error(_request: Request, err: Exception) -> JSONResponse:
    status, code, field = classify(err)
    headers = {"WWW-Authenticate": "Bearer"} if status == 401 else None
    return JSONResponse(error_body(code, str(err), field), status_code=status, headers=headers)


async def _validation_error(_request: Request, err: Exception) -> JSONResponse:
    assert isinstance(err, RequestValidationError)
    problems = []
    first_field = None
    for e in err.errors():
        loc = ".".join(str(p) for p in e.get("loc", ()))
        msg = str(e.get("msg", "")).removeprefix("Value error, ")
        inner = _FIELD.match(msg)  # a model-level check names its field first: 'grid: ...'
        if inner and e.get("type") == "value_error":
            loc, msg = f"{loc}.{inner.group(1)}", msg[inner.end() :]
        elif e.get("type") in ("union_tag_invalid", "union_tag_not_found"):
            loc = f"{loc}.{str(e.get('ctx', {}).get('discriminator', '')).strip(chr(39))}"
        first_field = first_field or loc
        problems.append(f"{loc}: {msg}")
    return JSONResponse(
        error_body("validation_error", "; ".join(problems), first_field), status_code=422
    )


HTTP_CODES = {
    400: "bad_request",
    401: "unauthorized",
    404: "not_found",
    405: "method_not_allowed",
    413: "too_large",
    422: "validation_error",
}
"""Error codes of the routing and body-parsing errors FastAPI raises itself (others: bad_request)."""


def allowed_methods(request: Request) -> list[str]:
    """Every method some route serves at this path (a 405's ``Allow`` header)."""
    return [
        method
        for method in ("DELETE", "GET", "HEAD", "PATCH", "POST", "PUT")
        if any(
            route.matches({**request.scope, "type": "http", "method": method})[0] == Match.FULL
            for route in request.app.router.routes
        )
    ]


async def _http_error(request: Request, err: Exception) -> JSONResponse:
    assert isinstance(err, StarletteHTTPException)
    status = err.status_code
    code = HTTP_CODES.get(status, "bad_request" if status < 500 else "internal")
    headers = dict(err.headers or {})
    message = str(err.detail)
    if status == 405:
        allow = allowed_methods(request)
        headers["Allow"] = ", ".join(allow)
        message = f"{request.method} is not allowed here; allowed: {', '.join(allow)}"
    return JSONResponse(error_body(code, message), status_code=status, headers=headers or None)


async def _unexpected(request: Request, err: Exception) -> JSONResponse:
    log.exception("unexpected error on %s %s", request.method, request.url.path)
    return JSONResponse(
        error_body("internal", f"internal error ({type(err).__name__}); see the server log"),
        status_code=500,
    )


def install_error_handlers(app: FastAPI) -> None:
    """Map the exception tree, request validation and routing errors to JSON responses."""
    app.add_exception_handler(DiathermyError, _diathermy_error)
    app.add_exception_handler(RequestValidationError, _validation_error)
    app.add_exception_handler(StarletteHTTPException, _http_error)
    app.add_exception_handler(Exception, _unexpected)


ErrorResponses: dict[int | str, dict[str, object]] = {
    status: {"model": ErrorPublic, "description": desc}
    for status, desc in [
        (400, "bad request (e.g. an unknown field name)"),
        (401, "missing or unknown bearer token"),
        (404, "no such session (job, model, electrode, snapshot) for this token"),
        (409, "the session is busy stepping or restoring"),
        (413, "request body too large"),
        (422, "invalid input or over a limit; 'field' names it"),
        (429, "too many sessions (or active jobs) for this token"),
        (503, "the session's engine process ended; retry (it reloads from disk)"),
    ]
}
"""The error responses every session route documents."""


AuthResponses: dict[int | str, dict[str, object]] = {
    401: {"model": ErrorPublic, "description": "missing or unknown bearer token"}
}
"""The error response of a route that only needs a token."""
