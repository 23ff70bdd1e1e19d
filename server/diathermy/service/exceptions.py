"""Service-level errors (on top of ``diathermy.errors``); ``errors.py`` maps each to a status."""

from __future__ import annotations

from diathermy.errors import DiathermyError


class ServiceError(DiathermyError):
    """Base of the errors only the service raises; ``field`` names the offending input."""

    def __init__(self, message: str, *, field: str | None = None) -> None:
        super().__init__(message)
        self.field = field


class AuthError(ServiceError):
    """No bearer token, or one the server does not know."""


class SessionNotFoundError(ServiceError, LookupError):
    """No session with this id belongs to the caller (other owners' sessions look the same)."""


class SessionBusyError(ServiceError):
    """The session is stepping (or restoring) on behalf of another request."""


class LimitExceededError(ServiceError):
    """A request asks for more than the server's limits allow (grid, steps, sessions, size)."""


class TooManySessionsError(LimitExceededError):
    """The token already owns the maximum number of sessions."""


class RequestTooLargeError(LimitExceededError):
    """A request body or stream message is larger than allowed."""


class NotFoundError(ServiceError, LookupError):
    """No job or model by that id for the caller."""


class TooManyJobsError(LimitExceededError):
    """The token already has the maximum number of queued and running jobs."""


class BadRequestError(ServiceError, ValueError):
    """A request is well-formed but asks for something that does not exist (field, snapshot)."""


class EngineProcessError(ServiceError):
    """A session's engine process ended; the session reloads from disk on next use."""
