"""Service benchmark (loopback only, bounded): stream throughput and control latency for 1, 4
and 16 clients against the engine's own rate, bytes per frame, and server memory under a slow
client.

    python benchmarks/service.py [--grids 17x17x33,default,33x33x65] [--seconds 4]

``default`` in --grids is the default scene's own graded grid (its ``resolution``).

Targets (issue 23): frames/s per client >= 0.9 x the engine's steps/s; the engine's steps/s with
16 clients within 10 % of its rate with none; p99 control-to-frame <= 2 step times + 20 ms.

The server runs in a child process (so its memory is its own); clients are asyncio websockets
clients plus one raw-socket client that reads nothing. Writes benchmarks/results/service.md.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing
import os
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "server"), str(ROOT)]

import httpx  # noqa: E402
from websockets.asyncio.client import connect  # noqa: E402

from benchmarks.service_client import RawStream  # noqa: E402
from benchmarks.service_procs import (  # noqa: E402
    children_cpu_s,
    cpu_ticks,
    rss_mib,
    run_queue_s,
    steal_share,
    tree_cpu_s,
)
from benchmarks.service_tables import write_report  # noqa: E402
from diathermy.scene.builtin import builtin_scene  # noqa: E402
from diathermy.service.cpus import format_cpus, parse_cpus  # noqa: E402
from diathermy.service.encoding import unpack  # noqa: E402

TOKEN = "bench-token"
QUICK_CUT = {
    "name": "quick-cut",
    "block_m": [0.02, 0.01, 0.01],
    "electrodes": [{"position_m": [0.01, 0.005], "power_w": 200.0}],
}
FIELDS = ["temperature", "displacement"]
DTYPE = "float32"  # the stream clients' subscription (--dtype); forked clients inherit it
REGION = "volume"  # and its region (--region)
CLIENTS_PER_PROC = 4
FULL_DECODE = False  # service_trace.py --full-decode: the old client
STEADY = {"name": "default-electrothermal", "effects": ["electric", "thermal"]}
"""The built-in default scene (50 W) without vaporization and mechanics: a steady step cost, so
that rows compare like with like (with them, steps slow ~100x once the tissue boils)."""
DEFAULT_RESOLUTION = builtin_scene("default").resolution.model_dump(mode="json")  # type: ignore[union-attr]
"""The default scene's graded grid (``--grids default``)."""
DEFAULT_LABEL = (
    "x".join(map(str, builtin_scene("default").node_shape)) + " (the default scene's graded grid)"
)
"""The heading of the default grid's table."""


def serve_child(args: argparse.Namespace) -> None:
    """The child process: the app with the real engine under uvicorn."""
    import uvicorn

    from diathermy.runtime import configure_threads
    from diathermy.service import Settings, create_app
    from diathermy.service.cpus import place_server
    from diathermy.service.jsonlog import configure_logging

    configure_threads()  # as `diathermy serve` does: one BLAS thread per engine

    settings = Settings(
        port=args.port,
        data_dir=Path(args.data_dir),
        tokens=[TOKEN],
        max_stream_rate_hz=1000.0,
        max_sessions_per_token=64,
        autosave_interval_s=3600,
        log_level="WARNING",
    )
    configure_logging("WARNING")
    place_server(settings.engine_cpus)  # as `diathermy serve` does (DIATHERMY_ENGINE_CPUS)
    app = create_app(settings)
    uvicorn.run(
        app,
        host="127.0.0.1",
        port=args.port,
        ws="websockets-sansio",
        ws_per_message_deflate=False,
        log_config=None,
        access_log=False,
        ws_max_size=settings.max_message_bytes,
    )


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Server:
    def __init__(
        self, data_dir: Path, script: Path | None = None, env: dict[str, str] | None = None
    ) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.ws = f"ws://127.0.0.1:{self.port}"
        self.proc = subprocess.Popen(
            [
                sys.executable,
                str(script or __file__),
                "serve-child",
                "--port",
                str(self.port),
                "--data-dir",
                str(data_dir),
            ],
            env=env,
        )
        self.wait_ready(timeout_s=60.0)
        self.http = httpx.Client(
            base_url=self.url, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=120
        )

    def wait_ready(self, timeout_s: float) -> None:
        """Poll ``/readyz``; raise at once if the server exits, or after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while True:
            code = self.proc.poll()
            if code is not None:
                raise RuntimeError(f"the benchmark server exited with code {code} before ready")
            try:
                if httpx.get(self.url + "/readyz", timeout=5).status_code == 200:
                    return
            except httpx.TransportError:
                pass
            if time.monotonic() > deadline:
                self.stop()
                raise RuntimeError(f"the benchmark server was not ready after {timeout_s:.0f} s")
            time.sleep(0.1)

    def session(self, grid: list[int] | None, scene: dict[str, Any] | None = None) -> str:
        """A new session on ``grid`` (None: the default scene's own graded grid)."""
        if grid is None:
            own = {"resolution": DEFAULT_RESOLUTION}
            body: dict[str, Any] = {"scene": {**(scene or {}), **own}}
        else:
            body = (
                {"scene": {**scene, "grid": grid}}
                if scene
                else {"builtin": "default", "grid": grid}
            )
        r = self.http.post("/v1/sessions", json=body)
        r.raise_for_status()
        return str(r.json()["id"])

    def step_until_cut(self, sid: str, max_steps: int = 40) -> int:
        for _ in range(max_steps):
            rep = self.http.post(f"/v1/sessions/{sid}/step").json()["reports"][-1]
            if rep["cut_volume_m3"]:
                return int(rep["step"])
        raise RuntimeError("no cut")

    def stop(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


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


def parse_grid(text: str) -> list[int] | None:
    """NZxNYxNX, or None for ``default`` (the default scene's own graded grid)."""
    return None if text == "default" else [int(x) for x in text.split("x")]


def warm_session(server: Server, grid: list[int] | None) -> str:
    """A fresh session of the steady scene, past its first step (the first electric solve)."""
    sid = server.session(grid, STEADY)
    server.http.post(f"/v1/sessions/{sid}/step", json={"n": 2}).raise_for_status()
    return sid


def engine_alone(server: Server, sid: str, seconds: float) -> float:
    """Steps/s of a session stepped over REST with no stream client (the engine's own rate);
    requests of about a second each, so that HTTP costs next to nothing per step."""
    t = time.monotonic()
    server.http.post(f"/v1/sessions/{sid}/step", json={"n": 5}).raise_for_status()
    n = max(2, min(200, round(5 / (time.monotonic() - t))))
    t0 = time.monotonic()
    steps = 0
    while time.monotonic() - t0 < seconds or steps < 10:
        server.http.post(f"/v1/sessions/{sid}/step", json={"n": n}).raise_for_status()
        steps += n
    return steps / (time.monotonic() - t0)


def grid_rows(
    server: Server, grid: list[int] | None, clients: list[int], seconds: float, reps: int
) -> tuple[float, list[dict[str, Any]]]:
    """Engine alone and 1, 4, 16 clients, interleaved ``reps`` times on fresh sessions (the
    machine is shared, so its load drifts); medians per row, the 16-client ratio per repetition."""
    alone: list[float] = []
    alone_wait: list[float] = []
    runs: dict[int, list[dict[str, Any]]] = {n: [] for n in clients}
    for _ in range(reps):
        for n in [0, *clients]:
            sid = warm_session(server, grid)
            ticks = cpu_ticks()
            if n == 0:
                q0, t0 = run_queue_s(server.proc.pid), time.monotonic()
                alone.append(engine_alone(server, sid, seconds))
                alone_wait.append((run_queue_s(server.proc.pid) - q0) / (time.monotonic() - t0))
            else:
                q0 = run_queue_s(server.proc.pid)
                c0, t0 = children_cpu_s(), time.monotonic()
                s0, e0 = tree_cpu_s(server.proc.pid)
                runs[n].append(fan_out(server, sid, n, seconds, 1000.0))
                runs[n][-1].pop("outs")
                wall = time.monotonic() - t0
                s1, e1 = tree_cpu_s(server.proc.pid)
                runs[n][-1]["engine_wait"] = (run_queue_s(server.proc.pid) - q0) / wall
                runs[n][-1]["server_cpu"] = (s1 - s0) / wall
                engine = sum(t - e0.get(p, 0.0) for p, t in e1.items())
                runs[n][-1]["engine_cpu"] = engine / wall
                runs[n][-1]["client_cpu"] = (children_cpu_s() - c0) / wall
                runs[n][-1]["vs_alone"] = runs[n][-1]["steps_per_s"] / alone[-1]
                runs[n][-1]["steal"] = steal_share(ticks)
            print(n, alone[-1] if n == 0 else runs[n][-1], flush=True)
            server.http.delete(f"/v1/sessions/{sid}")
    rows = []
    for n in clients:
        row: dict[str, Any] = {"clients": n, "reps": reps}
        keys = ("steps_per_s", "fps_per_client", "p50_ms", "p99_ms", "vs_alone", "step_p50_ms")
        keys += ("step_p99_ms", "step_max_ms", "beyond_p99_ms")
        for key in (*keys, "server_cpu", "engine_cpu", "client_cpu", "engine_wait", "steal"):
            row[key] = statistics.median(r[key] for r in runs[n])
        row["samples"] = sum(r["samples"] for r in runs[n])
        row["dropped"] = sum(r["dropped"] for r in runs[n])
        row["p99_bound_ms"] = statistics.median(2e3 / r["steps_per_s"] + 20 for r in runs[n])
        row["alone_wait"] = statistics.median(alone_wait)
        rows.append(row)
    return statistics.median(alone), rows


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


async def frame_sizes(server: Server, sid: str) -> list[dict[str, Any]]:
    rows = []
    url = f"{server.ws}/v1/sessions/{sid}/stream"
    async with connect(
        url, additional_headers={"Authorization": f"Bearer {TOKEN}"}, max_size=None
    ) as ws:
        await ws.recv()
        for region in ("volume", "top", "surface"):
            for dtype in ("float32", "float16"):
                sub = {"type": "subscribe", "fields": FIELDS, "dtype": dtype, "region": region}
                await ws.send(json.dumps(sub))
                while True:
                    raw = await ws.recv()
                    msg = unpack(raw)
                    if msg["type"] == "frame":
                        break
                verts = msg["surface"]["vertices"]["shape"][0] if region == "surface" else None
                rows.append(
                    {"region": region, "dtype": dtype, "bytes": len(raw), "surface_vertices": verts}
                )
    return rows


SLOW_MAX_S = 15.0
"""Longest slow-client run: the server closes a client that has not answered its ping for the
ping interval plus timeout (uvicorn's 20 + 20 s), and this one reads nothing."""


def slow_client_memory(server: Server, sid: str, seconds: float) -> dict[str, Any]:
    from tests.service.rawws import RawWebSocket

    base, _ = rss_mib(server.proc.pid)
    ws = RawWebSocket("127.0.0.1", server.port, f"/v1/sessions/{sid}/stream", TOKEN)
    ws.recv()
    ws.send_text(json.dumps({"type": "subscribe", "fields": FIELDS}))
    ws.send_text(json.dumps({"type": "run", "rate_hz": 1000}))
    peak = base
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:  # read nothing
        peak = max(peak, rss_mib(server.proc.pid)[0])
        time.sleep(0.1)
    ws.send_text(json.dumps({"type": "pause"}))
    last = None
    try:
        while True:
            msg = ws.recv(timeout=2.0)
            if msg["type"] == "frame":
                last = msg
    except TimeoutError:
        pass
    ws.close()
    steps = server.http.get(f"/v1/sessions/{sid}").json()["step"]
    return {
        "rss_before_mib": base,
        "rss_peak_mib": peak,
        "steps": steps,
        "dropped": last["dropped"] if last else None,
        "seconds": seconds,
    }


def bench_engine_cpus(text: str) -> list[int]:
    """``--engine-cpus``: 'auto' is the last CPU this process may use when it may use 2 or more."""
    if text == "none":
        return []
    if text == "auto":
        cpus = sorted(os.sched_getaffinity(0))
        return cpus[-1:] if len(cpus) >= 2 else []
    return parse_cpus(text)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    sub = p.add_subparsers(dest="cmd")
    c = sub.add_parser("serve-child")
    c.add_argument("--port", type=int, required=True)
    c.add_argument("--data-dir", required=True)
    p.add_argument(
        "--grids",
        default="17x17x33,default,33x33x65",
        help="session grids NZxNYxNX or 'default' (the default scene's graded grid), comma-separated",
    )
    p.add_argument("--slow-grid", default="17x17x33", help="grid of the slow-client run")
    p.add_argument("--seconds", default="3,6", help="seconds per row, per grid (comma-separated)")
    p.add_argument("--reps", type=int, default=3, help="interleaved repetitions per grid")
    p.add_argument("--clients", default="1,4,16")
    p.add_argument(
        "--clients-per-proc",
        type=int,
        default=CLIENTS_PER_PROC,
        help="stream clients per forked client process (the clients share the server's CPUs "
        "when placed: with small frames one event loop for all of them costs less than several; "
        "with large ones several spread the reading)",
    )
    p.add_argument(
        "--dtype",
        choices=["float32", "float16"],
        default="float32",
        help="the stream clients' subscription dtype (float16: 0.51x the bytes)",
    )
    p.add_argument(
        "--region",
        choices=["volume", "top"],
        default="volume",
        help="the stream clients' subscription region (top: the top face, 1/nz of the bytes)",
    )
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "service.md"))
    p.add_argument(
        "--engine-cpus",
        default="auto",
        help="the server's DIATHERMY_ENGINE_CPUS (engine processes there, the server and this "
        "script's clients on the other CPUs); 'auto': the last CPU when there are 2 or more, "
        "'none': no placement",
    )
    args = p.parse_args()
    if args.cmd == "serve-child":
        serve_child(args)
        return
    global DTYPE, REGION
    DTYPE, REGION = args.dtype, args.region
    import tempfile

    slow_grid = [int(x) for x in args.slow_grid.split("x")]
    engine_cpus = bench_engine_cpus(args.engine_cpus)
    set_clients_per_proc(args.clients_per_proc)
    load = os.getloadavg()
    ticks = cpu_ticks()
    tables = []
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "DIATHERMY_ENGINE_CPUS": format_cpus(engine_cpus)}
        server = Server(Path(tmp), env=env)
        if engine_cpus:  # the clients (forked from here) off the engines' CPUs, as the server
            os.sched_setaffinity(0, set(os.sched_getaffinity(0)) - set(engine_cpus))
        try:
            grids = args.grids.split(",")
            seconds = [float(x) for x in args.seconds.split(",")]
            seconds = (seconds + [seconds[-1]] * len(grids))[: len(grids)]
            clients = [int(x) for x in args.clients.split(",")]
            for grid_text, secs in zip(grids, seconds, strict=True):
                grid = parse_grid(grid_text)
                alone, rows = grid_rows(server, grid, clients, secs, args.reps)
                label = DEFAULT_LABEL if grid_text == "default" else grid_text
                tables.append((label, alone, rows))
            first = parse_grid(args.grids.split(",")[0])
            sid = server.session(first, QUICK_CUT)
            server.step_until_cut(sid)
            sizes = asyncio.run(frame_sizes(server, sid))
            print(sizes, flush=True)
            sid = server.session(slow_grid, STEADY)
            slow = slow_client_memory(server, sid, seconds=min(2 * seconds[0], SLOW_MAX_S))
            slow_sizes = asyncio.run(frame_sizes(server, sid))
            slow["frame_bytes"] = slow_sizes[0]["bytes"]
            slow["grid"] = args.slow_grid
            print(slow, flush=True)
        finally:
            server.stop()
    meta = {
        "fields": FIELDS,
        "dtype": DTYPE,
        "region": REGION,
        "clients_per_proc": CLIENTS_PER_PROC,
        "default_grid": DEFAULT_LABEL.split(" ")[0],
        "engine_cpus": engine_cpus,
        "server_cpus": sorted(os.sched_getaffinity(0)),  # this script's, after pinning
        "seconds": args.seconds,
        "argv": " ".join(sys.argv[1:]),
        "load": " / ".join(f"{x:.1f}" for x in (*load, *os.getloadavg())),
        "steal": 100 * steal_share(ticks),
    }
    write_report(Path(args.out), meta, tables, sizes, slow)
    print(Path(args.out).read_text())


if __name__ == "__main__":
    main()
