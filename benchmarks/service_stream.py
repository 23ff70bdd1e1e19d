"""The service benchmark's stream clients: each subscribes, sends electrode controls and times
the frames that show them applied (``stream_client``); ``fan_out`` runs n of them in forked
processes and sums up their rates and latencies.

The module's settings (``FIELDS``, ``DTYPE``, ``REGION``, ``CLIENTS_PER_PROC``,
``FULL_DECODE``) are set by ``service.py`` and ``service_trace.py`` before the clients fork,
which inherit them.
"""

from __future__ import annotations

import asyncio
import json
import multiprocessing
import statistics
import time
from typing import TYPE_CHECKING, Any

from websockets.asyncio.client import connect

from benchmarks.service_client import RawStream
from benchmarks.service_server import TOKEN
from diathermy.service.encoding import unpack

if TYPE_CHECKING:
    from benchmarks.service_server import Server

FIELDS = ["temperature", "displacement"]
DTYPE = "float32"  # the stream clients' subscription (--dtype); forked clients inherit it
REGION = "volume"  # and its region (--region)
CLIENTS_PER_PROC = 4
FULL_DECODE = False  # service_trace.py --full-decode: the old client


def control_latencies(
    sent: dict[int, float], acked: dict[int, int], frames: list[tuple[float, int, int]]
) -> list[tuple[float, int]]:
    """(seconds, step) from sending each control to the first frame received after it whose
    ``control_id`` is at least the control's (ids grow in the order the engine applies them,
    so that frame is the first to show it applied), and that frame's step. ``sent``: tag ->
    send time; ``acked``: tag -> control id; ``frames``: (receive time, control_id, step) in
    order."""
    out = []
    for tag, t_sent in sent.items():
        cid = acked.get(tag)
        if cid is None:
            continue
        got = next(((t, s) for t, c, s in frames if t > t_sent and c >= cid), None)
        if got is not None:
            out.append((got[0] - t_sent, got[1]))
    return out


class FullClient:
    """The old client (``service_trace.py --full-decode``): the ``websockets`` library, every
    message decoded whole."""

    def __init__(self, ws: Any) -> None:
        self.ws = ws

    @classmethod
    async def open(cls, url: str) -> FullClient:
        headers = {"Authorization": f"Bearer {TOKEN}"}
        return cls(await connect(url, additional_headers=headers, max_size=None))

    async def recv(self, timeout_s: float) -> tuple[float, dict[str, Any]]:
        raw = await asyncio.wait_for(self.ws.recv(), timeout=timeout_s)
        t = time.monotonic()
        return t, dict(unpack(raw))

    def send_text(self, text: str) -> None:
        asyncio.ensure_future(self.ws.send(text))

    def close(self) -> None:
        asyncio.ensure_future(self.ws.close())


async def open_client(url: str) -> Any:
    if FULL_DECODE:
        return await FullClient.open(url)
    host_port, path = url.removeprefix("ws://").split("/", 1)
    host, port = host_port.split(":")
    return await RawStream.open(host, int(port), "/" + path, TOKEN)


async def stream_client(
    url: str,
    *,
    index: int,
    rate_hz: float | None,
    t_start: float,
    seconds: float,
    out: dict[str, Any],
) -> None:
    """Subscribe, (if ``rate_hz``) start the run, send an electrode control every 0.25 s from
    ``t_start`` (monotonic clock) for ``seconds``, and time the frames that show them applied."""
    ws = await open_client(url)
    try:
        await ws.recv(30.0)  # hello
        sub = {"type": "subscribe", "fields": FIELDS, "dtype": DTYPE, "region": REGION}
        ws.send_text(json.dumps(sub))
        if rate_hz is not None:
            ws.send_text(json.dumps({"type": "run", "rate_hz": rate_hz}))
        frames: list[tuple[float, int, int]] = []  # (receive time, control_id, step) of each
        counted: list[tuple[float, int]] = []  # (receive time, step) from t_start
        sent: dict[int, float] = {}  # tag -> send time
        acked: dict[int, int] = {}  # tag -> control id
        walls: dict[int, float] = {}  # step -> the engine's wall time for it (frame report)
        tag = index * 1_000_000  # unique across clients (the trace joins on it)
        t_end = t_start + seconds
        next_control = t_start
        dropped = 0
        while True:
            now = time.monotonic()
            if now >= t_end:
                break
            if now >= next_control:
                tag += 1
                sent[tag] = now
                power = 50.0 if tag % 2 else 49.0
                ws.send_text(json.dumps({"type": "electrode", "power_w": power, "tag": tag}))
                next_control = now + 0.25
            try:
                t, msg = await ws.recv(0.05)  # so a control goes out just after a frame
            except TimeoutError:
                continue
            if msg["type"] == "ack" and msg.get("tag") in sent:
                acked[msg["tag"]] = msg["control_id"]
            elif msg["type"] == "frame":
                frames.append((t, msg["control_id"], msg["step"]))
                if msg.get("report"):
                    walls[msg["step"]] = float(msg["report"]["wall_s"])
                if t >= t_start:
                    counted.append((t, msg["step"]))
                    dropped = msg["dropped"]
        if rate_hz is not None:
            ws.send_text(json.dumps({"type": "pause"}))
            await asyncio.sleep(0.05)
    finally:
        ws.close()
    span = counted[-1][0] - counted[0][0] if len(counted) > 1 else float("nan")
    out["fps"] = (len(counted) - 1) / span
    out["steps_per_s"] = (counted[-1][1] - counted[0][1]) / span
    out["latencies"] = control_latencies(sent, acked, frames)
    out["dropped"] = dropped
    out["sent"], out["acked"], out["frames"], out["walls"] = sent, acked, frames, walls


def client_process(
    url: str, indices: list[int], rate_hz: float, t_start: float, seconds: float, conn: Any
) -> None:
    """One client process: the stream clients ``indices`` (client 0 starts the run)."""
    outs: list[dict[str, Any]] = [{} for _ in indices]

    async def clients() -> None:
        await asyncio.gather(
            *[
                stream_client(
                    url,
                    index=i,
                    rate_hz=rate_hz if i == 0 else None,
                    t_start=t_start,
                    seconds=seconds,
                    out=o,
                )
                for i, o in zip(indices, outs, strict=True)
            ]
        )

    asyncio.run(clients())
    conn.send(outs)
    conn.close()


def fan_out(server: Server, sid: str, n: int, seconds: float, rate_hz: float) -> dict[str, Any]:
    """``n`` clients in ``client_procs(n)`` forked processes (so that one Python process
    decoding every stream is not what the latency measures); their results and CPU seconds."""
    url = f"{server.ws}/v1/sessions/{sid}/stream"
    procs = client_procs(n)
    ctx = multiprocessing.get_context("fork")
    t_start = time.monotonic() + 1.0 + 0.05 * n  # all connected and subscribed by then
    running = []
    for p in range(procs):
        ours, theirs = ctx.Pipe(duplex=False)
        indices = list(range(p, n, procs))
        proc = ctx.Process(
            target=client_process, args=(url, indices, rate_hz, t_start, seconds, theirs)
        )
        proc.start()
        theirs.close()
        running.append((proc, ours))
    outs: list[dict[str, Any]] = []
    for proc, ours in running:
        outs += ours.recv()
        proc.join()
        if proc.exitcode:
            raise RuntimeError(f"a benchmark client process exited with code {proc.exitcode}")
    lat = sorted(x for o in outs for x, _ in o["latencies"])
    q = statistics.quantiles(lat, n=100) if len(lat) >= 2 else [float("nan")] * 99
    by_step = {k: v for o in outs for k, v in o["walls"].items()}
    walls = sorted(by_step.values())
    qw = statistics.quantiles(walls, n=100) if len(walls) >= 2 else [float("nan")] * 99
    beyond = [  # beyond the engine's own time for the frame's step and the one before it
        x - by_step[s] - by_step[s - 1]
        for o in outs
        for x, s in o["latencies"]
        if s in by_step and s - 1 in by_step
    ]
    qb = statistics.quantiles(beyond, n=100) if len(beyond) >= 2 else [float("nan")] * 99
    steps_per_s = statistics.median(o["steps_per_s"] for o in outs)
    return {
        "clients": n,
        "procs": procs,
        "rate_hz": rate_hz,
        "steps_per_s": steps_per_s,
        "fps_per_client": statistics.median(o["fps"] for o in outs),
        "fps_total": sum(o["fps"] for o in outs),
        "p50_ms": 1e3 * q[49],
        "p99_ms": 1e3 * q[98],
        "samples": len(lat),
        "dropped": sum(o["dropped"] for o in outs),
        "step_p50_ms": 1e3 * qw[49],
        "step_p99_ms": 1e3 * qw[98],
        "step_max_ms": 1e3 * walls[-1] if walls else float("nan"),
        "beyond_p99_ms": 1e3 * qb[98],
        "outs": outs,
    }


def set_clients_per_proc(n: int) -> None:
    """How many stream clients share one forked client process (at least 1)."""
    global CLIENTS_PER_PROC
    CLIENTS_PER_PROC = max(1, n)


def client_procs(n: int) -> int:
    """Client processes for ``n`` clients: up to ``CLIENTS_PER_PROC`` clients each."""
    return max(1, -(-n // CLIENTS_PER_PROC))
