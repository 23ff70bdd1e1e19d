"""Where a control's latency goes: timestamps along the path of each electrode control of the
service benchmark, from the client's send to the frame that shows it applied.

    python benchmarks/service_trace.py [--grid 33x33x65] [--clients 1,4,16] [--seconds 4]

The server child of ``service.py`` runs with hooks that log, on the machine's monotonic clock
(one clock for all processes): the control handled by the event loop, sent to the engine,
applied by the engine, journaled; each step started, done and its frame encoded in the engine
process, the reply sent and received by the server, journaled, handed to the clients, written
to each client's socket; and the client's receive. Writes ``benchmarks/results/service_trace.md``
(median and p99 of each segment per client count). ``--full-decode --procs-per-16 1`` replays
the old client (one process, every frame decoded).
"""

from __future__ import annotations

import argparse
import contextvars
import json
import os
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "server"), str(ROOT)]

TRACE_ENV = "DIATHERMY_TRACE_DIR"
PLAIN_ORDER_ENV = "DIATHERMY_TRACE_PLAIN_ORDER"
_lock = threading.Lock()
_files: dict[int, Any] = {}
_tag: contextvars.ContextVar[int | None] = contextvars.ContextVar("tag", default=None)


def emit(ev: str, **data: Any) -> None:
    """Append one event (a JSON line) to this process's trace file."""
    pid = os.getpid()
    with _lock:
        f = _files.get(pid)
        if f is None:
            f = _files[pid] = open(  # noqa: SIM115 (kept open for the process)
                Path(os.environ[TRACE_ENV]) / f"trace-{pid}.jsonl", "a", buffering=1
            )
        f.write(json.dumps({"ev": ev, "pid": pid, **data}) + "\n")


def install_engine_hooks() -> None:
    """In the forkserver (so in every engine process): time the step op, its frame header
    (the step is done then) and each reply's send."""
    from multiprocessing.connection import Connection

    from diathermy.service import engine_ops as ops

    step_frames, apply_control, frame_header = ops.step_frames, ops.apply_control, ops.frame_header
    stamps: dict[str, float] = {}

    def traced_header(sim: Any, *, session_id: str, control_id: int) -> dict[str, Any]:
        stamps["done"] = time.monotonic()
        return frame_header(sim, session_id=session_id, control_id=control_id)

    def traced_step(sim: Any, subs: Any, sid: str, control_id: int) -> Any:
        t0 = time.monotonic()
        stamps.clear()
        out = step_frames(sim, subs, sid, control_id)
        t2 = time.monotonic()
        cid = ops.ControlCount.last
        emit("e_step", step=int(sim.step_index), cid=cid, t0=t0, t1=stamps.get("done", t2), t2=t2)
        return out

    def traced_control(sim: Any, name: str, changes: Any, control_id: int) -> Any:
        out = apply_control(sim, name, changes, control_id)
        emit("e_ctl", cid=out[0], t=time.monotonic())
        return out

    send = Connection.send

    def traced_send(self: Connection, obj: Any) -> None:
        t0 = time.monotonic()
        send(self, obj)
        emit("e_send", t0=t0, t1=time.monotonic(), rid=obj[0] if isinstance(obj, tuple) else None)

    ops.step_frames = traced_step  # type: ignore[assignment]
    ops.apply_control = traced_control  # type: ignore[assignment]
    ops.frame_header = traced_header  # type: ignore[assignment]
    Connection.send = traced_send  # type: ignore[method-assign]


def install_server_hooks() -> None:
    """In the server process: the control's and each step's path through the server."""
    from diathermy.service import driver, hub, registry, stream
    from diathermy.service.engine_process import RemoteSim
    from diathermy.service.messages import ElectrodeControl

    handle = stream.StreamConnection._handle

    async def traced_handle(self: Any, msg: Any, drv: Any) -> None:
        if isinstance(msg, ElectrodeControl) and isinstance(msg.tag, int):
            _tag.set(msg.tag)
            self.trace_client = msg.tag // 1_000_000
            emit("handle", tag=msg.tag, t=time.monotonic())
        await handle(self, msg, drv)

    offer = registry.SessionRecord.offer

    def traced_offer(self: Any, control: Any) -> Any:
        t = time.monotonic()
        fut = offer(self, control)
        emit("offer", tag=_tag.get(), t=t, batch=fut is not None)
        return fut

    receive = RemoteSim.receive

    def traced_receive(self: Any) -> Any:
        reply = receive(self)
        is_step = isinstance(reply.value, tuple) and isinstance(reply.value[1], dict)
        emit("recv", step=self.step_index if is_step else None, rid=reply.id, t=time.monotonic())
        return reply

    applied = driver.control_applied

    def traced_applied(rec: Any, reg: Any, control: Any, result: Any) -> Any:
        out = applied(rec, reg, control, result)
        emit("ctl_journal", cid=result[0], t=time.monotonic())
        return out

    log_step = registry.SessionRegistry.log_step

    def traced_log_step(self: Any, rec: Any) -> None:
        log_step(self, rec)
        emit("journal", step=rec.sim.step_index, t=time.monotonic())

    deliver = hub.StreamHub.deliver

    def traced_deliver(self: Any, frames: Any) -> int:
        out = deliver(self, frames)
        steps = {f.step for f in frames.values()}
        emit("deliver", step=min(steps) if steps else None, t=time.monotonic())
        return out

    async def traced_sender(self: Any) -> None:
        while True:
            frame = await self.sub.slot.wait()
            while self.replies:
                await self.ws.send_bytes(stream.pack(self.replies.popleft()))
            if frame is not None:
                t0 = time.monotonic()
                await self.ws.send_bytes(frame.to_bytes(self.sub.slot.dropped))
                self.state.metrics.frames_sent.inc()
                if self.sub.first_shown_by(frame):
                    self.sub.awaiting = 0
                client = getattr(self, "trace_client", None)
                emit("write", step=frame.step, client=client, t0=t0, t1=time.monotonic())

    stream.StreamConnection._handle = traced_handle  # type: ignore[method-assign]
    registry.SessionRecord.offer = traced_offer  # type: ignore[method-assign]
    RemoteSim.receive = traced_receive  # type: ignore[method-assign]
    driver.control_applied = traced_applied
    registry.SessionRegistry.log_step = traced_log_step  # type: ignore[method-assign]
    hub.StreamHub.deliver = traced_deliver  # type: ignore[method-assign]
    stream.StreamConnection._sender = traced_sender  # type: ignore[method-assign]


if os.environ.get(TRACE_ENV) and __name__ == "benchmarks.service_trace":
    install_engine_hooks()  # imported by the forkserver (engine_process.PRELOAD)


def serve_child(args: argparse.Namespace) -> None:
    """The benchmark's server child with the hooks: engine ones through the forkserver."""
    from diathermy.service import engine_process

    engine_process.PRELOAD.append("benchmarks.service_trace")
    install_server_hooks()
    if os.environ.get(PLAIN_ORDER_ENV):  # the order before: subscribers in the order they came
        from diathermy.service import hub

        hub.Subscriber.first_shown_by = lambda self, frame: False  # type: ignore[method-assign]
    svc().serve_child(args)


def svc() -> Any:
    import benchmarks.service as module

    return module


SEGMENTS = [
    ("client sends -> server's event loop handles it", "handle", "send"),
    ("event loop -> control sent to the engine", "offer", "handle"),
    ("waits for the step in progress (engine applies it)", "apply", "offer"),
    ("applied -> its step starts", "t0", "apply"),
    ("its step (engine)", "t1", "t0"),
    ("frame encoded (engine)", "t2", "t1"),
    ("reply: pickle, pipe, unpickle -> server thread", "recv", "t2"),
    ("journaled", "journal", "recv"),
    ("handed to the clients' slots", "deliver", "journal"),
    ("event loop picks it up for this client", "w0", "deliver"),
    ("written to this client's socket", "w1", "w0"),
    ("socket -> client has the message", "got", "w1"),
    ("total (send -> frame received)", "got", "send"),
]


def load_events(trace_dir: Path) -> list[dict[str, Any]]:
    events = []
    for path in trace_dir.glob("trace-*.jsonl"):
        for line in path.read_text().splitlines():
            if line.strip():
                events.append(json.loads(line))
    return events


def breakdown(
    events: list[dict[str, Any]], outs: list[dict[str, Any]], a: float, b: float
) -> tuple[list[dict[str, float]], list[float], list[float]]:
    """Each control's timestamps along its path (a row per control) and the steps' times."""

    def t_of(e: dict[str, Any]) -> float:
        return float(e.get("t", e.get("t0", 0.0)))

    evs = [e for e in events if a <= t_of(e) <= b]
    steps = {e["step"]: e for e in evs if e["ev"] == "e_step"}
    applied = {e["cid"]: e["t"] for e in evs if e["ev"] == "e_ctl"}
    handled = {e["tag"]: e["t"] for e in evs if e["ev"] == "handle"}
    offered = {e["tag"]: e["t"] for e in evs if e["ev"] == "offer"}
    recv = {e["step"]: e["t"] for e in evs if e["ev"] == "recv" and e["step"] is not None}
    journal = {e["step"]: e["t"] for e in evs if e["ev"] == "journal"}
    deliver = {e["step"]: e["t"] for e in evs if e["ev"] == "deliver"}
    writes = {(e["step"], e["client"]): e for e in evs if e["ev"] == "write"}
    rows = []
    for out in outs:
        for tag, t_send in out["sent"].items():
            cid = out["acked"].get(tag)
            if cid is None or cid not in applied:
                continue
            got = next(((t, s) for t, c, s in out["frames"] if t > t_send and c >= cid), None)
            first = min((s for s, e in steps.items() if e["cid"] >= cid), default=None)
            if got is None or first is None or first not in recv:
                continue
            e = steps[first]
            w = writes.get((got[1], tag // 1_000_000), {})
            row = {
                "send": t_send,
                "handle": handled.get(tag, float("nan")),
                "offer": offered.get(tag, float("nan")),
                "apply": applied[cid],
                "t0": e["t0"],
                "t1": e["t1"],
                "t2": e["t2"],
                "recv": recv[first],
                "journal": journal.get(first, float("nan")),
                "deliver": deliver.get(first, float("nan")),
                "w0": w.get("t0", float("nan")),
                "w1": w.get("t1", float("nan")),
                "got": got[0],
                "later_frame": float(got[1] != first),
            }
            rows.append(row)
    step_times = [e["t1"] - e["t0"] for e in steps.values()]
    last_write: dict[int, float] = {}
    for (step, _), w in writes.items():
        last_write[step] = max(last_write.get(step, 0.0), w["t1"])
    spread = [t - deliver[s] for s, t in last_write.items() if s in deliver]
    return rows, step_times, spread


def segment_table(
    results: list[tuple[int, list[dict[str, float]], list[float], float]],
) -> list[str]:
    head = "| segment | " + " | ".join(
        f"{n} client{'s' if n > 1 else ''} p50 / p99 ms" for n, *_ in results
    )
    lines = [head + " |", "|---|" + "---:|" * len(results)]
    for name, end, start in SEGMENTS:
        cells = []
        for _, rows, *_ in results:
            vals = sorted(
                1e3 * (r[end] - r[start]) for r in rows if r[end] == r[end] and r[start] == r[start]
            )
            if len(vals) < 2:
                cells.append("n/a")
                continue
            q = statistics.quantiles(vals, n=100)
            cells.append(f"{q[49]:.1f} / {q[98]:.1f}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines.append(
        "| step time (every step) | "
        + " | ".join(f"{1e3 * statistics.median(st):.1f}" for _, _, st, *_ in results)
        + " |"
    )
    lines.append(
        "| every step: handed to the clients -> written to the last one | "
        + " | ".join(
            f"{1e3 * statistics.median(sp):.1f} / {1e3 * max(sp):.1f} (max)" if sp else "n/a"
            for *_, sp in results
        )
        + " |"
    )
    lines.append(
        "| controls whose frame the client did not get (a later one showed it) | "
        + " | ".join(
            f"{sum(r['later_frame'] for r in rows):.0f} of {len(rows)}" for _, rows, *_ in results
        )
        + " |"
    )
    lines.append(
        "| benchmark p99 ms (its own measure) / bound | "
        + " | ".join(
            f"{p99:.1f} / {2e3 * statistics.median(st) + 20:.0f}" for _, _, st, p99, _ in results
        )
        + " |"
    )
    return lines


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    sub = p.add_subparsers(dest="cmd")
    c = sub.add_parser("serve-child")
    c.add_argument("--port", type=int, required=True)
    c.add_argument("--data-dir", required=True)
    p.add_argument("--grid", default="33x33x65")
    p.add_argument("--clients", default="1,4,16")
    p.add_argument("--seconds", type=float, default=4.0)
    p.add_argument("--full-decode", action="store_true", help="clients decode whole frames")
    p.add_argument("--clients-per-proc", type=int, default=4)
    p.add_argument(
        "--plain-order", action="store_true", help="write frames in subscriber order (as before)"
    )
    p.add_argument("--label", default="")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "service_trace.md"))
    args = p.parse_args()
    if args.cmd == "serve-child":
        serve_child(args)
        return
    bench = svc()
    bench.CLIENTS_PER_PROC = args.clients_per_proc
    bench.FULL_DECODE = args.full_decode
    grid = [int(x) for x in args.grid.split("x")]
    results = []
    load = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        trace_dir = Path(tmp) / "trace"
        trace_dir.mkdir()
        env = {**os.environ, TRACE_ENV: str(trace_dir)}
        if args.plain_order:
            env[PLAIN_ORDER_ENV] = "1"
        server = bench.Server(Path(tmp) / "data", script=Path(__file__), env=env)
        try:
            for n in [int(x) for x in args.clients.split(",")]:
                sid = bench.warm_session(server, grid)
                a = time.monotonic()
                run = bench.fan_out(server, sid, n, args.seconds, 1000.0)
                b = time.monotonic()
                server.http.delete(f"/v1/sessions/{sid}")
                time.sleep(0.2)
                rows, step_times, spread = breakdown(load_events(trace_dir), run["outs"], a, b)
                results.append((n, rows, step_times, run["p99_ms"], spread))
                print(n, len(rows), run["p50_ms"], run["p99_ms"], flush=True)
        finally:
            server.stop()
    mode = "whole frames decoded" if args.full_decode else "header only decoded"
    lines = [
        f"### {args.label or args.grid}: {mode}, up to {args.clients_per_proc} clients per "
        f"client process",
        "",
        f"Load average {' / '.join(f'{x:.1f}' for x in (*load, *os.getloadavg()))}.",
        "",
        *segment_table(results),
        "",
    ]
    text = "\n".join(lines)
    print(text)
    with open(args.out, "a", encoding="utf-8") as f:
        f.write(text + "\n")


if __name__ == "__main__":
    main()
