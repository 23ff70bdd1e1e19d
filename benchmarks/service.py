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
import resource
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
DEFAULT_RESOLUTION = builtin_scene("default").resolution.model_dump(mode="json")  # type: ignore[union-attr]
"""The default scene's graded grid (``--grids default``)."""
DEFAULT_LABEL = (
    "x".join(map(str, builtin_scene("default").node_shape)) + " (the default scene's graded grid)"
)
"""The built-in default scene (50 W) without vaporization and mechanics: a steady step cost, so
that rows compare like with like (with them, steps slow ~100x once the tissue boils)."""


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


def rss_mib(pid: int) -> tuple[float, float]:
    """(current, peak) resident set of a process in MiB."""
    status = Path(f"/proc/{pid}/status").read_text()
    val = {ln.split(":")[0]: ln.split()[1] for ln in status.splitlines() if ln.startswith("Vm")}
    return int(val["VmRSS"]) / 1024, int(val["VmHWM"]) / 1024


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


def cpu_s(pid: int) -> float:
    """CPU seconds (user + system, all threads) a process has used."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def children_cpu_s() -> float:
    """CPU seconds of the benchmark's client processes that have ended (forked and joined)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def descendants(pid: int) -> list[int]:
    """Child processes of ``pid``, recursively (the forkserver and the engine processes)."""
    out: list[int] = []
    for task in Path(f"/proc/{pid}/task").glob("*/children"):
        for child in task.read_text().split():
            out += [int(child), *descendants(int(child))]
    return out


def cpu_ticks() -> tuple[int, int]:
    """(steal, total) clock ticks of all CPUs so far (``/proc/stat``): steal is the time the
    hypervisor ran other virtual machines on this one's CPUs."""
    fields = [int(x) for x in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    return fields[7], sum(fields[:8])


def steal_share(start: tuple[int, int]) -> float:
    """Share of the CPUs' time since ``start`` (``cpu_ticks``) that the host took."""
    steal, total = cpu_ticks()
    return (steal - start[0]) / max(1, total - start[1])


def run_queue_s(pid: int) -> float:
    """Seconds the processes under ``pid`` (the engines) spent runnable but waiting for a CPU
    (``/proc/<pid>/schedstat``, main threads)."""
    total = 0.0
    for child in descendants(pid):
        try:
            total += int(Path(f"/proc/{child}/schedstat").read_text().split()[1]) / 1e9
        except (FileNotFoundError, ProcessLookupError, IndexError):
            continue
    return total


def tree_cpu_s(pid: int) -> tuple[float, dict[int, float]]:
    """(CPU seconds of ``pid``, {descendant pid: its CPU seconds})."""
    kids = {}
    for child in descendants(pid):
        try:
            kids[child] = cpu_s(child)
        except (FileNotFoundError, ProcessLookupError):
            continue
    return cpu_s(pid), kids


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


def fan_table(grid: str, alone: float, fan: list[dict[str, Any]]) -> list[str]:
    """The streaming table of one grid, with the targets checked."""
    lines = [
        f"### Grid {grid}" if grid != "default" else f"### Grid {DEFAULT_LABEL}",
        "",
        f"Engine alone (REST steps, no stream client): **{alone:.1f} steps/s** "
        f"({1e3 / alone:.1f} ms per step), median of {fan[0]['reps']} runs; the engine waited "
        f"for a CPU {100 * fan[0]['alone_wait']:.0f} % of the time.",
        "",
        "| clients | steps/s | vs alone | frames/s per client | per client / steps/s | "
        "latency p50 ms | latency p99 ms | p99 bound ms | samples | frames dropped | "
        "engine step ms p50 / p99 / max | p99 beyond its two steps ms | "
        "CPU server / engine / clients | engine waits for a CPU | host steal | targets |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in fan:
        bound = r["p99_bound_ms"]
        fps_ok = r["fps_per_client"] >= 0.9 * r["steps_per_s"]
        rate_ok = r["clients"] != 16 or r["vs_alone"] >= 0.9
        lat_ok = r["p99_ms"] <= bound
        verdict = (
            "met"
            if fps_ok and rate_ok and lat_ok
            else "MISSED "
            + ", ".join(
                name
                for name, ok in (("fps", fps_ok), ("steps/s", rate_ok), ("p99", lat_ok))
                if not ok
            )
        )
        lines.append(
            f"| {r['clients']} | {r['steps_per_s']:.1f} | {r['vs_alone']:.2f} | "
            f"{r['fps_per_client']:.1f} | {r['fps_per_client'] / r['steps_per_s']:.2f} | "
            f"{r['p50_ms']:.1f} | {r['p99_ms']:.1f} | {bound:.0f} | {r['samples']} | "
            f"{r['dropped']} | {r['step_p50_ms']:.0f} / {r['step_p99_ms']:.0f} / "
            f"{r['step_max_ms']:.0f} | {r['beyond_p99_ms']:.1f} | "
            f"{r['server_cpu']:.2f} / {r['engine_cpu']:.2f} / "
            f"{r['client_cpu']:.2f} | {100 * r['engine_wait']:.0f} % | "
            f"{100 * r['steal']:.0f} % | {verdict} |"
        )
    return lines + [""]


def write_report(
    path: Path,
    meta: dict[str, Any],
    tables: list[tuple[str, float, list[dict[str, Any]]]],
    sizes: list[dict[str, Any]],
    slow: dict[str, Any],
) -> None:
    lines = [
        "# Service benchmark",
        "",
        f"`python benchmarks/service.py {meta['argv']}` — the real engine, fields "
        f"{', '.join(FIELDS)} ({DTYPE} {REGION}), loopback, {meta['seconds']} s per row, "
        f"{os.cpu_count()} cores shared by the server, the clients and other jobs (load average "
        f"{meta['load']}).",
        "",
        placement_text(meta["engine_cpus"], meta["server_cpus"]),
        "",
        "## Streaming: N clients on one session, as fast as the engine steps",
        "",
        "One client sends `run` at 1000 steps/s (more than the engine can do: the session steps "
        "as fast as it goes); all subscribe to the same fields. *Engine alone* is the same "
        "server stepping a session over REST (requests of about a second of steps) with no "
        "client streaming. Each "
        "row is the median of the repetitions; the configurations run interleaved (alone, 1, 4, "
        "16, alone, ...) on fresh sessions, and *vs alone* is the median of each run's ratio to "
        "the alone run just before it, so that the shared machine's drifting load cancels. "
        f"Clients: up to {CLIENTS_PER_PROC} per forked client process (`service_client.py`, "
        "`--clients-per-proc`), each a WebSocket "
        "client that reads every byte of every frame off its socket into one buffer and keeps "
        "only the message's header (step, `control_id`, report, `dropped`; the arrays come "
        "last and are skipped unread), so that the latency is the service's and not that of "
        "a Python client decoding 16 x 1.2 MB per step in one process (the client before this "
        "one, `service_trace.py` replays it). "
        "CPU: cores used during the row by the server process, by its engine processes and by "
        "the benchmark's client processes (which share the cores with them; placed, the "
        "server's). Latency: from "
        "sending an electrode control message to the first frame whose `control_id` shows it "
        "applied (the ack gives the control's id; the frame may come before the ack); every "
        "client sends one every 0.25 s, right after a frame arrives, which is the worst phase: "
        "the step in progress has just begun. Frames dropped: coalesced for clients that fell "
        "behind (summed). Engine step: the engine's own wall time per step (the frames' "
        "reports); *p99 beyond its two steps*: each control's latency less the wall times of the "
        "step that showed it and the step before (the one it waited for), i.e. what the service "
        "adds. Targets: frames/s per client >= 0.9 x steps/s, steps/s with 16 "
        "clients >= 0.9 x alone, p99 <= 2 step times + 20 ms, step time = 1 / steps/s of the "
        "row (a control waits for the step in progress, then its own step).",
        "",
        "Scene: the built-in `default` (50 W) with only its electric and thermal effects, on "
        "the grids below (`default`: the scene's own graded grid, 1 mm under the electrode, "
        f"{DEFAULT_LABEL.split(' ')[0]}): a steady cost per step, so that rows compare "
        "like with like (with vaporization and mechanics a step costs ~100x more once the "
        "tissue boils, which happens within a row). Frames carry temperature and displacement "
        f"({DTYPE} {REGION}).",
        "",
    ]
    for grid, alone, fan in tables:
        lines += fan_table(grid, alone, fan)
    lines += [
        "How: each loaded session's engine runs in a process of its own "
        "(`engine_process.py`, forked by a forkserver that imported the engine once); a worker "
        "thread of the server keeps two step requests in flight, so the engine starts the next "
        "step while the server journals the last one, and electrode controls go to the engine "
        "at once, which applies them before its next step (ahead of a queued step) and answers "
        "in the order it ran them, the order the server journals them in. The engine process "
        "takes the step and builds and msgpack-encodes "
        "the frame once per distinct subscription; the server journals the step "
        "(`journal.py`) before it hands the bytes to the clients, and the event loop only "
        "prefixes each client's `dropped` counter and writes the bytes (no per-message "
        "compression: float fields barely compress and deflating a frame per client cost more "
        "than the step). So the sockets' writes no longer take GIL time from the engine, and "
        "with BLAS on one thread (`DIATHERMY_BLAS_THREADS`, default 1, as `diathermy serve` "
        "sets) the engine takes one core and leaves the other to the event loop, the kernel's "
        "copies and the clients; with `DIATHERMY_ENGINE_CPUS` (`cpus.py`) the scheduler no "
        "longer decides that: the engine processes are pinned to their CPUs and the server "
        "(with the clients, here) to the others, so the fan-out never takes the engine's core. "
        "The frame of a step is written first to the clients whose last "
        "electrode control it is the first to show (`hub.py`), and the senders are woken one "
        "per turn of the event loop, so that a control that arrives while a frame goes out to "
        "16 clients is read after one write, not sixteen.",
        "",
        "CPU column: *server* is the server process (event loop, HTTP, journal), *engine* its "
        "engine processes, *clients* the benchmark's client processes. Every step moves 16 x the "
        "frame over loopback (150 kB on 17x17x33, 0.6 MB on the default grid, 1.2 MB on "
        "33x33x65): the server's writes, "
        "the kernel's copies and the clients' reads take that much CPU besides the engine's "
        "(on the server's CPUs when placed). *Engine waits for a CPU*: the share of the "
        "row's wall time the engine process was runnable but not running (its run-queue delay, "
        "`/proc/<pid>/schedstat`): time the other jobs, the server and the clients took from "
        "it (placed, only other jobs can). *Host steal*: the share of all CPUs' time during the "
        "row that the hypervisor gave to other virtual machines (`/proc/stat`); the guest does "
        "not see it as waiting, but a step that loses its CPU for a while is that much slower, "
        "so a row with more than a few per cent of it measures the host, not the service "
        f"(the whole run: {meta['steal']:.1f} %).",
        "",
        *trace_section(),
        "## Bytes per frame",
        "",
        "A 2 x 1 x 1 cm block under 200 W, stepped until it cuts.",
        "",
        "| region | dtype | bytes | surface vertices |",
        "|---|---|---:|---:|",
    ]
    for r in sizes:
        lines.append(
            f"| {r['region']} | {r['dtype']} | {r['bytes']} | "
            f"{'' if r['surface_vertices'] is None else r['surface_vertices']} |"
        )
    v32 = next(r["bytes"] for r in sizes if r["region"] == "volume" and r["dtype"] == "float32")
    v16 = next(r["bytes"] for r in sizes if r["region"] == "volume" and r["dtype"] == "float16")
    lines += ["", f"float16 / float32 volume: {v16 / v32:.2f}.", ""]
    lines += [
        "## Server memory under a slow client",
        "",
        f"A raw-socket client subscribes to volume frames on grid {slow['grid']}, starts the "
        f"run and reads nothing for {slow['seconds']} s.",
        "",
        "| steps taken | frames dropped (coalesced) | server RSS before MiB | "
        "server RSS peak MiB | growth MiB | frame bytes |",
        "|---:|---:|---:|---:|---:|---:|",
        f"| {slow['steps']} | {slow['dropped']} | {slow['rss_before_mib']:.0f} | "
        f"{slow['rss_peak_mib']:.0f} | {slow['rss_peak_mib'] - slow['rss_before_mib']:.0f} | "
        f"{slow['frame_bytes']} |",
        "",
        f"Without coalescing the server would have queued about "
        f"{slow['steps'] * slow['frame_bytes'] / 2**20:.0f} MiB for this client.",
        "",
    ]
    path.write_text("\n".join(lines), encoding="utf-8")


def bench_engine_cpus(text: str) -> list[int]:
    """``--engine-cpus``: 'auto' is the last CPU this process may use when it may use 2 or more."""
    if text == "none":
        return []
    if text == "auto":
        cpus = sorted(os.sched_getaffinity(0))
        return cpus[-1:] if len(cpus) >= 2 else []
    return parse_cpus(text)


def placement_text(engine_cpus: list[int], server_cpus: list[int]) -> str:
    """The results' sentence on CPU placement."""
    if not engine_cpus:
        return (
            "CPU placement: none (`--engine-cpus none`): the server, its engine processes and "
            "the clients run wherever the scheduler puts them."
        )
    rest = format_cpus(server_cpus)
    return (
        f"CPU placement: `DIATHERMY_ENGINE_CPUS={format_cpus(engine_cpus)}` (`--engine-cpus`): "
        f"the engine processes run on CPU {format_cpus(engine_cpus)}, the server process (event "
        f"loop, worker threads, journal, the socket writes and the kernel's copies they make) on "
        f"CPU {rest}, and the benchmark pins its own client processes to CPU {rest} too: a real "
        "deployment's clients run on other machines, and here they would otherwise take the "
        "engine's core."
    )


def trace_section() -> list[str]:
    """The latency breakdown of ``service_trace.py`` (its last results), headings demoted."""
    path = ROOT / "benchmarks" / "results" / "service_trace.md"
    if not path.exists():
        return []
    text = path.read_text(encoding="utf-8").strip().splitlines()
    return [("#" + ln if ln.startswith("#") else ln) for ln in text] + [""]


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
                tables.append((grid_text, alone, rows))
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
