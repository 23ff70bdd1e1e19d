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
import os
import statistics
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "server"), str(ROOT)]

from websockets.asyncio.client import connect  # noqa: E402

from benchmarks import service_stream as stream  # noqa: E402
from benchmarks.service_procs import (  # noqa: E402
    children_cpu_s,
    cpu_ticks,
    rss_mib,
    run_queue_s,
    steal_share,
    tree_cpu_s,
)
from benchmarks.service_server import (  # noqa: E402
    DEFAULT_LABEL,
    TOKEN,
    Server,
    serve_child,
)
from benchmarks.service_stream import (  # noqa: E402
    FIELDS,
    client_procs,
    control_latencies,
    fan_out,
    set_clients_per_proc,
)
from benchmarks.service_tables import write_report  # noqa: E402
from diathermy.service.cpus import format_cpus, parse_cpus  # noqa: E402
from diathermy.service.encoding import unpack  # noqa: E402

QUICK_CUT = {
    "name": "quick-cut",
    "block_m": [0.02, 0.01, 0.01],
    "electrodes": [{"position_m": [0.01, 0.005], "power_w": 200.0}],
}
STEADY = {"name": "default-electrothermal", "effects": ["electric", "thermal"]}
"""The built-in default scene (50 W) without vaporization and mechanics: a steady step cost, so
that rows compare like with like (with them, steps slow ~100x once the tissue boils)."""
__all__ = ["Server", "client_procs", "control_latencies", "fan_out", "serve_child"]


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
        default=stream.CLIENTS_PER_PROC,
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
    stream.DTYPE, stream.REGION = args.dtype, args.region
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
        "dtype": stream.DTYPE,
        "region": stream.REGION,
        "clients_per_proc": stream.CLIENTS_PER_PROC,
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
