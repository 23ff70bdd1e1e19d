"""Where a control's latency goes: timestamps along the path of each electrode control of the
service benchmark, from the client's send to the frame that shows it applied.

    python benchmarks/service_trace.py [--grids 17x17x33,33x33x65] [--clients 1,4,16]

The server child of ``service.py`` runs with hooks that log, on the machine's monotonic clock
(one clock for all processes): the control handled by the event loop, sent to the engine,
applied by the engine, journaled; each step started, done and its frame encoded in the engine
process, the reply sent and received by the server, journaled, handed to the clients, written
to each client's socket; and the client's receive. Writes ``benchmarks/results/service_trace.md``
(median and p99 of each segment per client count), for the service and client as they were
before (``before``: the ``websockets`` client decoding every frame in one process, frames written
in subscriber order, all senders woken at once, replies read with ``Connection.recv``) and as
they are (``now``).
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
        hub.wake_in_turn = _wake_all  # type: ignore[assignment]
        engine_process.ReplyReader = _ConnectionReader  # type: ignore[misc, assignment]
    svc().serve_child(args)


class _ConnectionReader:
    """The replies' reading before: ``Connection.recv``."""

    def __init__(self, conn: Any) -> None:
        self.conn = conn

    def recv(self) -> Any:
        return self.conn.recv()

    def close(self) -> None:
        pass


def _wake_all(slots: list[Any], sizes: list[int], now: int = 1) -> None:
    """The senders' wake-up before: all of them in one turn of the event loop."""
    for slot in slots:
        slot.wake()


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
) -> dict[str, Any]:
    """Each control's timestamps along its path (``rows``, one per control), and per step: the
    engine's step times (``steps``; ``after``: those right after a control) and the time from
    handing a frame to the clients to its write to the last one (``spread``)."""

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
    nan = float("nan")
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
            rows.append(
                {
                    "send": t_send,
                    "handle": handled.get(tag, nan),
                    "offer": offered.get(tag, nan),
                    "apply": applied[cid],
                    "t0": e["t0"],
                    "t1": e["t1"],
                    "t2": e["t2"],
                    "recv": recv[first],
                    "journal": journal.get(first, nan),
                    "deliver": deliver.get(first, nan),
                    "w0": w.get("t0", nan),
                    "w1": w.get("t1", nan),
                    "got": got[0],
                    "later_frame": float(got[1] != first),
                }
            )
    last_write: dict[int, float] = {}
    for (step, _), w in writes.items():
        last_write[step] = max(last_write.get(step, 0.0), w["t1"])
    return {
        "rows": rows,
        "steps": [e["t1"] - e["t0"] for e in steps.values()],
        "after": [
            e["t1"] - e["t0"]
            for s, e in steps.items()
            if s - 1 in steps and e["cid"] > steps[s - 1]["cid"]
        ],
        "spread": [t - deliver[s] for s, t in last_write.items() if s in deliver],
    }


def _q(vals: list[float]) -> tuple[float, float] | None:
    """(p50, p99) in ms."""
    vals = sorted(1e3 * v for v in vals if v == v)
    if len(vals) < 2:
        return None
    q = statistics.quantiles(vals, n=100)
    return q[49], q[98]


def segment_table(results: list[dict[str, Any]]) -> list[str]:
    """Median / p99 of each segment, a column per client count."""

    def cell(vals: list[float]) -> str:
        q = _q(vals)
        return "n/a" if q is None else f"{q[0]:.1f} / {q[1]:.1f}"

    head = " | ".join(f"{r['clients']} client{'s' if r['clients'] > 1 else ''}" for r in results)
    lines = [f"| p50 / p99 ms | {head} |", "|---|" + "---:|" * len(results)]
    for name, end, start in SEGMENTS:
        cells = [cell([r[end] - r[start] for r in res["rows"]]) for res in results]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    extra = [
        ("engine step, every step", lambda res: cell(res["steps"])),
        ("engine step, steps right after a control", lambda res: cell(res["after"])),
        (
            "frame handed to the clients -> written to the last one, every step",
            lambda res: cell(res["spread"]),
        ),
        (
            "controls whose own frame the client missed (a later one showed it)",
            lambda res: f"{sum(r['later_frame'] for r in res['rows']):.0f} of {len(res['rows'])}",
        ),
        (
            "the benchmark's p99 (its own measure) / bound 2 x median step + 20",
            lambda res: f"{res['p99_ms']:.1f} / {2e3 * statistics.median(res['steps']) + 20:.0f}",
        ),
    ]
    for name, fn in extra:
        lines.append(f"| {name} | " + " | ".join(fn(res) for res in results) + " |")
    return lines


VARIANTS = {
    "before": {
        "what": "as before this change: the old client (the `websockets` library, every frame "
        "decoded whole, 16 clients in one process), frames written in subscriber order, all "
        "senders woken in one turn, replies read with `Connection.recv`",
        "full_decode": True,
        "per_proc": 16,
        "plain": True,
    },
    "now": {
        "what": "now: the raw client (header only, 4 clients per process), the frame showing a "
        "client's control written to it first, senders woken a turn's worth of frame bytes at a "
        "time, replies read into one reused buffer",
        "full_decode": False,
        "per_proc": 4,
        "plain": False,
    },
    "placed": {
        "what": "placed: as *now*, with the engine processes on the last CPU "
        "(`DIATHERMY_ENGINE_CPUS`) and the server and the clients on the others",
        "full_decode": False,
        "per_proc": 4,
        "plain": False,
        "placed": True,
    },
}


def run_variant(
    name: str, grids: list[str], clients: list[int], seconds: float, dump: str | None
) -> dict[str, list[dict[str, Any]]]:
    """One server with the hooks; every grid and client count; the breakdown of each run."""
    bench = svc()
    v = VARIANTS[name]
    bench.stream.CLIENTS_PER_PROC, bench.stream.FULL_DECODE = v["per_proc"], v["full_decode"]
    out: dict[str, list[dict[str, Any]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        trace_dir = Path(tmp) / "trace"
        trace_dir.mkdir()
        env = {**os.environ, TRACE_ENV: str(trace_dir)}
        if v["plain"]:
            env[PLAIN_ORDER_ENV] = "1"
        mine = os.sched_getaffinity(0)
        engine_cpus = bench.bench_engine_cpus("auto" if v.get("placed") else "none")
        env["DIATHERMY_ENGINE_CPUS"] = bench.format_cpus(engine_cpus)
        server = bench.Server(Path(tmp) / "data", script=Path(__file__), env=env)
        if engine_cpus:  # the clients (forked from here) with the server
            os.sched_setaffinity(0, mine - set(engine_cpus))
        try:
            for grid in grids:
                out[grid] = []
                for n in clients:
                    sid = bench.warm_session(server, [int(x) for x in grid.split("x")])
                    a = time.monotonic()
                    run = bench.fan_out(server, sid, n, seconds, 1000.0)
                    b = time.monotonic()
                    server.http.delete(f"/v1/sessions/{sid}")
                    time.sleep(0.2)
                    res = breakdown(load_events(trace_dir), run["outs"], a, b)
                    res.update(clients=n, p99_ms=run["p99_ms"], p50_ms=run["p50_ms"])
                    out[grid].append(res)
                    print(name, grid, n, len(res["rows"]), run["p50_ms"], run["p99_ms"], flush=True)
                    if dump:
                        with open(dump, "a", encoding="utf-8") as f:
                            f.write(json.dumps({"variant": name, "grid": grid, **res}) + "\n")
        finally:
            server.stop()
            os.sched_setaffinity(0, mine)
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    sub = p.add_subparsers(dest="cmd")
    c = sub.add_parser("serve-child")
    c.add_argument("--port", type=int, required=True)
    c.add_argument("--data-dir", required=True)
    p.add_argument("--grids", default="17x17x33,33x33x65")
    p.add_argument("--clients", default="1,4,16")
    p.add_argument("--seconds", type=float, default=4.0)
    p.add_argument("--variants", default="before,now", help=f"of {', '.join(VARIANTS)}")
    p.add_argument("--dump", help="also append each run's timestamps (JSON lines) here")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "service_trace.md"))
    args = p.parse_args()
    if args.cmd == "serve-child":
        serve_child(args)
        return
    grids = args.grids.split(",")
    clients = [int(x) for x in args.clients.split(",")]
    load = os.getloadavg()
    runs = {
        v: run_variant(v, grids, clients, args.seconds, args.dump) for v in args.variants.split(",")
    }
    lines = [
        "# Where a control's latency goes",
        "",
        f"`python benchmarks/service_trace.py {' '.join(sys.argv[1:])}`: the service benchmark's "
        f"rows ({args.seconds} s each, one run per row) with timestamps along each control's "
        "path, on the machine's monotonic clock (one clock for every process). Load average "
        f"{' / '.join(f'{x:.1f}' for x in (*load, *os.getloadavg()))}.",
        "",
        "How to read it: a client sends its control right after a frame arrives, when the step "
        "in progress has just begun. The control waits for that step (*waits for the step in "
        "progress*: about one step less the previous frame's trip to the client), then for its "
        "own step, then for its frame's trip (from *frame encoded* to *socket -> client*); "
        "*applied -> its step starts* shows whether a queued step ran first (it does not: the "
        "engine takes a control ahead of a queued step). So the p50 is about 2 steps, the "
        "service's own share is the rows before the wait and from *frame encoded* on, and a "
        "p99 over the bound (2 x the row's step time + 20 ms) comes from steps slower than the "
        "row's median (*engine step*: the engine waiting for a CPU that the server, the clients "
        "and other jobs take, or, placed, its own step time varying on its own core) or from "
        "the frame's trip.",
        "",
    ]
    for grid in grids:
        for v, by_grid in runs.items():
            lines += [f"## {grid}, {VARIANTS[v]['what']}", "", *segment_table(by_grid[grid]), ""]
    text = "\n".join(lines)
    print(text)
    Path(args.out).write_text(text, encoding="utf-8")


if __name__ == "__main__":
    main()
