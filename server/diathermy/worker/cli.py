"""``diathermy worker`` and ``diathermy models``: the training worker and the model registry."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any


def _data_dir(args: argparse.Namespace) -> Path:
    return Path(args.data_dir or os.environ.get("DIATHERMY_DATA_DIR", "diathermy-data"))


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return value


def _cmd_worker(args: argparse.Namespace) -> int:
    from diathermy.worker.supervisor import Worker

    worker = Worker(_data_dir(args), poll_s=args.poll_s, lease_s=args.lease_s)
    worker.install_signal_handlers()
    print(f"worker {worker.id} on {worker.queue.path}", flush=True)
    n = worker.run(once=args.once)
    print(f"worker {worker.id} stopped after {n} job(s)", flush=True)
    return 0


def _format_model(info: Any, active: set[str]) -> str:
    grid = "x".join(str(n) for n in info.grid)
    err = info.metrics.get("val_mean_strain_energy_error")
    err_text = f"{err:.3g}" if isinstance(err, float) else "-"
    mark = "*" if info.ref in active else " "
    return (
        f"{mark} {info.ref:20s} grid {grid:10s} width {info.architecture.get('width', '?'):>3} "
        f"strain-energy error {err_text:>8s}  dataset {info.dataset_sha256[:12]}"
    )


def _cmd_models(args: argparse.Namespace) -> int:
    from diathermy.worker.registry import activate_model, active_models, list_models

    data_dir = _data_dir(args)
    if args.action == "activate":
        if not args.ref:
            raise SystemExit("diathermy models activate: give NAME:VERSION")
        info = activate_model(data_dir, args.ref)
        print(f"{info.ref} is now active for grid {'x'.join(str(n) for n in info.grid)}")
        return 0
    active = set(active_models(data_dir).values())
    models = list_models(data_dir)
    if not models:
        print(f"no models in {data_dir / 'models'}")
    for info in models:
        print(_format_model(info, active))
    return 0


def add_worker_parsers(subparsers: Any) -> None:
    """Add ``worker`` and ``models`` to the ``diathermy`` command line."""
    s = subparsers.add_parser("worker", help="run dataset and training jobs from the job queue")
    s.add_argument("--data-dir", help="the server's data directory (DIATHERMY_DATA_DIR)")
    s.add_argument("--poll-s", type=_positive_float, default=1.0, help="idle poll period (1 s)")
    s.add_argument(
        "--lease-s", type=_positive_float, default=30.0,
        help="a job whose worker is silent this long is resumed by another (30 s)",
    )  # fmt: skip
    s.add_argument("--once", action="store_true", help="exit when no job is runnable")
    s.set_defaults(func=_cmd_worker)

    s = subparsers.add_parser("models", help="list registered models, or activate one")
    s.add_argument("action", nargs="?", choices=["list", "activate"], default="list")
    s.add_argument("ref", nargs="?", help="NAME:VERSION to activate for its grid")
    s.add_argument("--data-dir", help="the server's data directory (DIATHERMY_DATA_DIR)")
    s.set_defaults(func=_cmd_models)
