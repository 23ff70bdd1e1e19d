"""The service benchmark's stream client: a WebSocket client that costs next to nothing per frame.

Every byte the server sends lands straight in one preallocated buffer (``asyncio.BufferedProtocol``:
the kernel's copy and nothing else); of each message only its first ``HEAD_BYTES`` are kept, which
hold a frame's header (step, ``control_id``, report, ``dropped``; the arrays come last). So the
latency the benchmark measures is the service's, not that of a Python client decoding 1.2 MB of
floats per frame (which, 16 clients in one process, took as long as the step itself).
"""

from __future__ import annotations

import asyncio
import base64
import os
import struct
import time
from collections import deque
from typing import Any

import msgpack

HEAD_BYTES = 1 << 14
"""Bytes kept of each message: a frame's header entries fit; its arrays are skipped unread."""
ARRAY_KEYS = ("fields", "surface")
BUFFER_BYTES = 1 << 22


def read_head(head: bytes, length: int) -> dict[str, Any]:
    """The entries of a msgpack map message before its arrays (``fields``, ``surface``), from
    its first bytes ``head`` (``length``: the message's size)."""
    if length <= len(head):
        return dict(msgpack.unpackb(head, raw=False))
    reader = msgpack.Unpacker(raw=False)
    reader.feed(head)
    out: dict[str, Any] = {}
    try:
        for _ in range(reader.read_map_header()):
            key = reader.unpack()
            if key in ARRAY_KEYS:
                return out
            out[key] = reader.unpack()
    except msgpack.OutOfData:
        raise RuntimeError(f"a message's header is over {len(head)} bytes") from None
    return out


class _Protocol(asyncio.BufferedProtocol):
    """Reads the upgrade response, then WebSocket frames (server frames are not masked)."""

    def __init__(self) -> None:
        self.buf = bytearray(BUFFER_BYTES)
        self.view = memoryview(self.buf)
        self.filled = 0
        self.upgraded: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self.messages: deque[tuple[float, int, bytes, int]] = deque()
        self.waiter: asyncio.Future[None] | None = None  # the reader's, while it waits
        self.transport: asyncio.Transport | None = None
        self._remaining = 0  # payload bytes of the current frame still to come
        self._opcode = 0  # of the message being read
        self._frame_op = 0  # of the frame being read (a control frame may interleave)
        self._fin = True
        self._head = bytearray()
        self._length = 0
        self._control = bytearray()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport

    def get_buffer(self, sizehint: int) -> memoryview:
        return self.view[self.filled :]

    def buffer_updated(self, nbytes: int) -> None:
        t = time.monotonic()
        self.filled += nbytes
        pos = 0
        if not self.upgraded.done():
            end = self.buf.find(b"\r\n\r\n", 0, self.filled)
            if end < 0:
                return
            status = bytes(self.buf[: self.buf.find(b"\r\n")])
            if b" 101 " not in status:
                self.upgraded.set_exception(ConnectionError(status.decode(errors="replace")))
                return
            self.upgraded.set_result(None)
            pos = end + 4
        while pos < self.filled:
            if self._remaining:
                n = min(self._remaining, self.filled - pos)
                self._take(self.view[pos : pos + n])
                self._remaining -= n
                pos += n
                if self._remaining == 0:
                    self._frame_done(t)
                continue
            header = self._parse_header(pos)
            if header is None:
                break  # a partial header: keep it for the next read
            pos, self._remaining = header
            if self._remaining == 0:
                self._frame_done(t)
        rest = self.filled - pos
        self.buf[:rest] = self.buf[pos : self.filled]  # at most a partial header
        self.filled = rest

    def _parse_header(self, pos: int) -> tuple[int, int] | None:
        avail = self.filled - pos
        if avail < 2:
            return None
        b0, b1 = self.buf[pos], self.buf[pos + 1]
        length, size = b1 & 0x7F, 2
        if length == 126:
            size = 4
        elif length == 127:
            size = 10
        if avail < size:
            return None
        if size == 4:
            (length,) = struct.unpack_from("!H", self.buf, pos + 2)
        elif size == 10:
            (length,) = struct.unpack_from("!Q", self.buf, pos + 2)
        self._fin, self._frame_op = bool(b0 & 0x80), b0 & 0x0F
        if self._frame_op >= 8:
            self._control = bytearray()
        elif self._frame_op != 0:  # a new message (0: its continuation)
            self._opcode, self._head, self._length = self._frame_op, bytearray(), 0
        return pos + size, length

    def _take(self, data: memoryview) -> None:
        if self._frame_op >= 8:
            self._control += data
            return
        self._length += len(data)
        if len(self._head) < HEAD_BYTES:
            self._head += data[: HEAD_BYTES - len(self._head)]

    def _frame_done(self, t: float) -> None:
        if self._frame_op == 9:  # ping: answer pong
            self.send(0xA, bytes(self._control))
        elif self._frame_op == 8:
            self._put((t, 8, bytes(self._control), len(self._control)))
        elif self._fin:
            self._put((t, self._opcode, bytes(self._head), self._length))

    def _put(self, message: tuple[float, int, bytes, int]) -> None:
        """Hand a message to the reader (a deque and one future: no asyncio.Queue per frame)."""
        self.messages.append(message)
        if self.waiter is not None and not self.waiter.done():
            self.waiter.set_result(None)

    def send(self, opcode: int, payload: bytes) -> None:
        """One masked frame (client frames must be)."""
        assert self.transport is not None
        n = len(payload)
        if n < 126:
            head = struct.pack("!BB", 0x80 | opcode, 0x80 | n)
        elif n < 65536:
            head = struct.pack("!BBH", 0x80 | opcode, 0x80 | 126, n)
        else:
            head = struct.pack("!BBQ", 0x80 | opcode, 0x80 | 127, n)
        mask = os.urandom(4)
        key = int.from_bytes((mask * (n // 4 + 1))[:n], "big") if n else 0
        body = (int.from_bytes(payload, "big") ^ key).to_bytes(n, "big") if n else b""
        self.transport.write(head + mask + body)

    def connection_lost(self, exc: Exception | None) -> None:
        if not self.upgraded.done():
            self.upgraded.set_exception(exc or ConnectionError("connection closed"))
        self._put((time.monotonic(), 8, b"", 0))


class RawStream:
    """One stream connection: ``recv`` gives (receive time, message head as a dict)."""

    def __init__(self, transport: asyncio.Transport, protocol: _Protocol) -> None:
        self.transport = transport
        self.protocol = protocol

    @classmethod
    async def open(cls, host: str, port: int, path: str, token: str) -> RawStream:
        loop = asyncio.get_running_loop()
        transport, protocol = await loop.create_connection(_Protocol, host, port)
        key = base64.b64encode(os.urandom(16)).decode()
        transport.write(
            f"GET {path} HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
            f"Authorization: Bearer {token}\r\n\r\n".encode()
        )
        await protocol.upgraded
        return cls(transport, protocol)

    async def recv(self, timeout_s: float) -> tuple[float, dict[str, Any]]:
        """The next message: (monotonic time its last byte arrived, its entries before the
        arrays); raises TimeoutError, or ConnectionError once the server closed."""
        protocol = self.protocol
        if not protocol.messages:  # a timer only when there is nothing to take yet
            protocol.waiter = asyncio.get_running_loop().create_future()
            try:
                async with asyncio.timeout(timeout_s):
                    await protocol.waiter
            finally:
                protocol.waiter = None
        t, opcode, head, length = protocol.messages.popleft()
        if opcode == 8:
            raise ConnectionError("the server closed the stream")
        return t, read_head(head, length)

    def send_text(self, text: str) -> None:
        self.protocol.send(0x1, text.encode())

    def close(self) -> None:
        self.protocol.send(0x8, struct.pack("!H", 1000))
        self.transport.close()
