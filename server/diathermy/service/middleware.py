"""ASGI middleware: request-size limit, access log, request metrics."""

from __future__ import annotations

import json
import logging
import time
from typing import Any

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from diathermy.service.errors import error_body
from diathermy.service.metrics import ServiceMetrics

log = logging.getLogger("diathermy.service.access")


class _TooLarge(Exception):
    pass


def _replay(body: bytes, receive: Receive) -> Receive:
    """A receive that hands the app the already-read body, then defers to the server."""
    sent = False

    async def replay() -> Message:
        nonlocal sent
        if not sent:
            sent = True
            return {"type": "http.request", "body": body, "more_body": False}
        return await receive()

    return replay


class LimitAndLogMiddleware:
    """Reject bodies over ``max_bytes`` with 413 JSON; log and count every HTTP request."""

    def __init__(self, app: ASGIApp, *, max_bytes: int, metrics: ServiceMetrics) -> None:
        self.app = app
        self.max_bytes = max_bytes
        self.metrics = metrics

    async def _reject(self, send: Send) -> None:
        body = json.dumps(
            error_body("too_large", f"request body is larger than {self.max_bytes} bytes", "body")
        ).encode()
        await send(
            {
                "type": "http.response.start",
                "status": 413,
                "headers": [(b"content-type", b"application/json")],
            }
        )
        await send({"type": "http.response.body", "body": body})

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        t0 = time.perf_counter()
        status = {"code": 500, "started": False}
        headers = dict(scope.get("headers", []))
        length = headers.get(b"content-length")
        if length is not None and length.isdigit() and int(length) > self.max_bytes:
            await self._reject(send)
            self._record(scope, 413, t0)
            return
        if length is None and scope["method"] not in ("GET", "HEAD", "OPTIONS", "DELETE"):
            # a chunked body has no length to check up front: read it (bounded), then replay it
            body, too_large = await self._read_bounded(receive)
            if too_large:
                await self._reject(send)
                self._record(scope, 413, t0)
                return
            receive = _replay(body, receive)
        seen = 0

        async def limited_receive() -> Message:
            nonlocal seen
            msg = await receive()
            if msg["type"] == "http.request":
                seen += len(msg.get("body", b""))
                if seen > self.max_bytes:
                    raise _TooLarge
            return msg

        async def tracking_send(msg: Message) -> None:
            if msg["type"] == "http.response.start":
                status["code"] = msg["status"]
                status["started"] = True
            await send(msg)

        try:
            await self.app(scope, limited_receive, tracking_send)
        except _TooLarge:
            if not status["started"]:
                await self._reject(send)
            status["code"] = 413
        self._record(scope, int(status["code"]), t0)

    async def _read_bounded(self, receive: Receive) -> tuple[bytes, bool]:
        """The whole request body, or (what was read, True) as soon as it passes the limit."""
        chunks: list[bytes] = []
        size = 0
        while True:
            msg = await receive()
            if msg["type"] != "http.request":
                return b"".join(chunks), False
            chunk = msg.get("body", b"")
            size += len(chunk)
            if size > self.max_bytes:
                return b"", True
            chunks.append(chunk)
            if not msg.get("more_body", False):
                return b"".join(chunks), False

    def _record(self, scope: Scope, status: int, t0: float) -> None:
        route: Any = scope.get("route")
        template = getattr(route, "path", None) or "unmatched"
        self.metrics.requests.labels(scope["method"], template, str(status)).inc()
        log.info(
            "request",
            extra={
                "method": scope["method"],
                "path": scope["path"],  # never the query string: it may hold a token
                "status": status,
                "ms": round(1e3 * (time.perf_counter() - t0), 2),
            },
        )
