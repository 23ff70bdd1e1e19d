"""The service benchmark's results file (``service.py``): the streaming table per grid with
its targets checked, the CPU placement, the latency breakdown of ``service_trace.py``, the bytes
per frame and the server's memory under a slow client."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from diathermy.service.cpus import format_cpus


def fan_table(grid: str, alone: float, fan: list[dict[str, Any]]) -> list[str]:
    """The streaming table of one grid (``grid``: its heading's label), with the targets
    checked."""
    lines = [
        f"### Grid {grid}",
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
    """The results file at ``path``: the streaming tables per grid (label, engine alone, rows),
    the trace's breakdown, the bytes per frame and the slow client's memory. ``meta``: the run's
    command line, seconds per row, load, host steal, CPU placement, and what the clients
    subscribed to (``fields``, ``dtype``, ``region``, ``clients_per_proc``)."""
    fields, dtype, region = meta["fields"], meta["dtype"], meta["region"]
    lines = [
        "# Service benchmark",
        "",
        f"`python benchmarks/service.py {meta['argv']}` — the real engine, fields "
        f"{', '.join(fields)} ({dtype} {region}), loopback, {meta['seconds']} s per row, "
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
        f"Clients: up to {meta['clients_per_proc']} per forked client process (`service_client.py`, "
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
        f"{meta['default_grid']}): a steady cost per step, so that rows compare "
        "like with like (with vaporization and mechanics a step costs ~100x more once the "
        "tissue boils, which happens within a row). Frames carry temperature and displacement "
        f"({dtype} {region}).",
        "",
    ]
    for label, alone, fan in tables:
        lines += fan_table(label, alone, fan)
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
        "electrode control it is the first to show (`hub.py`), and the senders are woken a "
        "turn's worth of frame bytes at a time (`hub.TURN_BYTES`, 256 kB: one 1.2 MB frame, or "
        "all 16 top-face frames of a few kB, per turn of the event loop), so that a control "
        "that arrives while large frames go out to 16 clients is read after one write, not "
        "sixteen.",
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
    path = Path(__file__).resolve().parent / "results" / "service_trace.md"
    if not path.exists():
        return []
    text = path.read_text(encoding="utf-8").strip().splitlines()
    return [("#" + ln if ln.startswith("#") else ln) for ln in text] + [""]
