"""Worker benchmark: the server's step latency while a training job runs beside it, against the
same server with an idle worker (ratio), on a small scene.

    python benchmarks/worker.py [--grid 9x9x17] [--steps 20] [--repeat 2]

Server and worker are separate processes on one data directory, as deployed. Each phase steps a
fresh session ``--steps`` times (one POST per step) and is repeated ``--repeat`` times,
alternating idle / training so machine drift hits both. Writes benchmarks/results/worker.md.
"""

from __future__ import annotations

import argparse
import os
import resource
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "server"), str(ROOT)]

import httpx  # noqa: E402

TOKEN = "bench-token"
ENV = {**os.environ, "PYTHONPATH": str(ROOT / "server")}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start(cmd: list[str], log: Path) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [sys.executable, "-m", "diathermy", *cmd],
        stdout=log.open("w"), stderr=subprocess.STDOUT, env=ENV, cwd=ROOT,
    )  # fmt: skip


def wait_job(api: httpx.Client, job_id: str, until: Any, timeout_s: float = 600) -> dict:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        job = api.get(f"/v1/jobs/{job_id}").json()
        if until(job):
            return job
        time.sleep(0.2)
    raise TimeoutError(f"job {job_id}: {job}")


def step_latencies(api: httpx.Client, grid: list[int], steps: int, min_s: float) -> list[float]:
    """Seconds per POST /step (n=1) on a fresh session of the default scene: at least
    ``steps`` of them and at least ``min_s`` seconds of stepping."""
    sid = api.post("/v1/sessions", json={"builtin": "default", "grid": grid}).json()["id"]
    api.post(f"/v1/sessions/{sid}/step")  # warm-up: first-step set-up is not the steady state
    out: list[float] = []
    start = time.perf_counter()
    while len(out) < steps or time.perf_counter() - start < min_s:
        t0 = time.perf_counter()
        resp = api.post(f"/v1/sessions/{sid}/step")
        if resp.status_code == 409:  # the server's autosave holds the session: not a step
            time.sleep(0.05)
            continue
        resp.raise_for_status()
        out.append(time.perf_counter() - t0)
    api.delete(f"/v1/sessions/{sid}")
    return out


def p90(xs: list[float]) -> float:
    return sorted(xs)[int(0.9 * (len(xs) - 1))]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", default="17x17x33", help="session and dataset grid NZxNYxNX")
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--min-seconds", type=float, default=8.0, help="of stepping per phase")
    ap.add_argument("--out", default=str(ROOT / "benchmarks/results/worker.md"))
    args = ap.parse_args()
    grid = [int(n) for n in args.grid.split("x")]
    tmp = Path(tempfile.mkdtemp(prefix="diathermy-worker-bench-"))
    port = free_port()
    server = start(
        ["serve", "--port", str(port), "--data-dir", str(tmp / "data"), "--token", TOKEN],
        tmp / "server.log",
    )
    worker = start(["worker", "--data-dir", str(tmp / "data"), "--poll-s", "0.5"], tmp / "w.log")
    api = httpx.Client(
        base_url=f"http://127.0.0.1:{port}",
        headers={"Authorization": f"Bearer {TOKEN}"},
        timeout=120,
    )
    try:
        for _ in range(300):
            try:
                if api.get("/healthz").status_code == 200:
                    break
            except httpx.TransportError:
                time.sleep(0.1)
        data_cfg = {"grid": grid, "n_scenarios": 6, "n_steps": 4, "seed": 1}
        ds = api.post("/v1/jobs", json={"kind": "dataset", "config": data_cfg}).json()["id"]
        wait_job(api, ds, lambda j: j["state"] == "succeeded")
        phases: dict[str, list[float]] = {"idle worker": [], "training beside": []}
        epoch_s: list[float] = []
        for _ in range(args.repeat):
            phases["idle worker"] += step_latencies(api, grid, args.steps, args.min_seconds)
            spec = {
                "kind": "training",
                "dataset": ds,
                "model_name": "bench",
                "train": {"width": 8, "epochs": 100_000, "patience": 100_000, "batch_size": 2},
            }
            tj = api.post("/v1/jobs", json=spec).json()["id"]
            wait_job(api, tj, lambda j: (j["progress"].get("epoch") or 0) >= 1)
            phases["training beside"] += step_latencies(api, grid, args.steps, args.min_seconds)
            api.post(f"/v1/jobs/{tj}/cancel")
            wait_job(api, tj, lambda j: j["state"] == "cancelled", timeout_s=60)
            lines = api.get(f"/v1/jobs/{tj}/log").json()["lines"]
            ts = [x["ts"] for x in lines if x["line"].startswith("epoch ")]
            epoch_s.extend(b - a for a, b in zip(ts, ts[1:], strict=False))
    finally:
        api.close()
        for proc in (worker, server):
            proc.terminate()
            proc.wait(timeout=30)
    write_table(args, phases, epoch_s)


def write_table(
    args: argparse.Namespace, phases: dict[str, list[float]], epoch_s: list[float]
) -> None:
    idle = statistics.median(phases["idle worker"])
    rss_mib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    rows = [
        f"| {name} | {len(xs)} | {1e3 * statistics.median(xs):.1f} | {1e3 * p90(xs):.1f} | "
        f"{statistics.median(xs) / idle:.2f} |"
        for name, xs in phases.items()
    ]
    text = "\n".join(
        [
            "# Worker benchmark: server step latency beside a training job",
            "",
            f"`python benchmarks/worker.py --grid {args.grid} --steps {args.steps} "
            f"--repeat {args.repeat} --min-seconds {args.min_seconds}`: default scene on grid {args.grid}, one `POST /step` "
            "(n=1) at a time on a fresh session per phase (at least --steps steps and "
            "--min-seconds of stepping); phases alternate idle / training.",
            "",
            "| worker | steps | median ms | p90 ms | median / idle |",
            "|---|---|---|---|---|",
            *rows,
            "",
            f"Training beside: CNN width 8 on a {args.grid} dataset (6 scenarios x 4 steps), "
            f"{statistics.median(epoch_s) if epoch_s else float('nan'):.1f} s per epoch "
            "(median, from the job log) while the server stepped. "
            f"Peak RSS of the largest child process (server, worker or job): {rss_mib:.0f} MiB.",
            "",
            f"Machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at the end "
            "(shared with other jobs), CPU only.",
            "",
            "Reading: server and worker share the cores; the job process runs torch with its own "
            "threads, so on a 2-core box a training job competes directly with the session's "
            "solver. Give the worker its own cores (`taskset`, a separate machine: the queue is a "
            "file on shared storage, or point workers at the same data directory) or lower its "
            "priority (`nice -n 10 diathermy worker`) where interactive latency matters.",
            "",
        ]
    )
    Path(args.out).write_text(text, encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
