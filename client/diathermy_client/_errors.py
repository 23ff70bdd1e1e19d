"""The SDK's exception tree; every error the SDK raises is a ``DiathermyError``.

::

    DiathermyError
    ├── AuthError           401 / stream close 4401: missing or unknown token
    ├── NotFound            404 / stream close 4404: no such session (or not yours), snapshot
    ├── InvalidRequest      400, 413, 422: ``field`` names the offending input
    │   └── LimitExceeded   422 limit_exceeded, 413 too_large, 429 too_many_sessions
    ├── Conflict            409: the session is busy stepping, or a checkpoint is unusable
    ├── ServerError         5xx, or a response the SDK cannot read
    ├── TransportError      the server could not be reached (after retries)
    ├── Timeout             no answer in time (also a builtins.TimeoutError)
    └── StreamClosed        the stream ended and could not be resumed
"""

from __future__ import annotations

import builtins
from typing import Any


class DiathermyError(Exception):
    """Base of every SDK error: ``status`` (HTTP, or None), server ``code``, ``message``, ``field``.

    Example::

        try:
            client.get_session("nope")
        except DiathermyError as err:
            print(err.status, err.code, err.message)
    """

    def __init__(
        self,
        message: str,
        *,
        status: int | None = None,
        code: str | None = None,
        field: str | None = None,
    ) -> None:
        super().__init__(message)
        self.message = message
        self.status = status
        self.code = code
        self.field = field

    def __str__(self) -> str:
        where = f" [{self.field}]" if self.field else ""
        head = f"{self.status} {self.code}: " if self.status is not None else ""
        return f"{head}{self.message}{where}"


class AuthError(DiathermyError):
    """The server does not know the token (or none was given)."""


class NotFound(DiathermyError):
    """No such session for this token, or no such snapshot; other tokens' sessions look the same."""


class InvalidRequest(DiathermyError):
    """The server refused an input; ``field`` names it (e.g. ``body.power_w``, ``scene.grid``)."""


class LimitExceeded(InvalidRequest):
    """Over a server limit: grid size or memory, steps per request, sessions per token, body size."""


class Conflict(DiathermyError):
    """The session is busy (code ``busy``: retry when its step ends) or its checkpoint is unusable."""


class ServerError(DiathermyError):
    """The server failed (5xx) or answered with something the SDK cannot read."""


class TransportError(DiathermyError):
    """The server could not be reached or the connection broke (after any retries)."""


class Timeout(DiathermyError, builtins.TimeoutError):
    """No answer within the timeout (after any retries)."""


class StreamClosed(DiathermyError):
    """The stream ended: ``close_code`` and ``reason`` as the server sent them (if it did)."""

    def __init__(
        self, message: str, *, close_code: int | None = None, reason: str | None = None, **kw: Any
    ) -> None:
        super().__init__(message, **kw)
        self.close_code = close_code
        self.reason = reason


_BY_STATUS: dict[int, type[DiathermyError]] = {
    400: InvalidRequest,
    401: AuthError,
    404: NotFound,
    409: Conflict,
    413: LimitExceeded,
    422: InvalidRequest,
    429: LimitExceeded,
}
_LIMIT_CODES = {"limit_exceeded", "too_large", "too_many_sessions"}


def error_for(status: int, body: Any) -> DiathermyError:
    """The SDK error for an HTTP error status and its (decoded JSON) body."""
    if isinstance(body, dict) and isinstance(body.get("message"), str):
        code, message, field = body.get("error"), body["message"], body.get("field")
    else:
        code, message, field = None, str(body)[:500] or f"HTTP {status}", None
    cls = _BY_STATUS.get(status, ServerError if status >= 500 else DiathermyError)
    if code in _LIMIT_CODES:
        cls = LimitExceeded
    return cls(message, status=status, code=code, field=field)
