"""``diathermy datagen CONFIG --out data.h5``: the Algorithm 1 dataset from a config file."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from diathermy.datagen.config import config_from_dict, load_config
from diathermy.datagen.generate import ENGINES, generate


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def _cmd_datagen(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    config = load_config(args.config)
    if args.scenarios is not None:
        config = config_from_dict({**config.model_dump(), "n_scenarios": args.scenarios})
    bar: Any = tqdm(total=config.n_scenarios, unit="scenario", disable=args.quiet, desc="datagen")

    def advance(index: int) -> None:
        if bar.n == 0 and index > 0:
            bar.update(index)  # scenarios a resumed file already held
        bar.update(1)

    try:
        summary = generate(
            config,
            Path(args.out),
            engine=args.engine,
            workers=args.workers,
            resume=args.resume,
            on_commit=advance,
            scheduler_address=args.scheduler,
        )
    finally:
        bar.close()
    print(
        f"{summary.path}: {summary.complete_scenarios} scenarios, {summary.samples} samples "
        f"({summary.computed_scenarios} computed, {summary.reused_shards} reused shards) "
        f"in {summary.wall_s:.1f} s on {summary.workers} {summary.engine} worker(s)"
    )
    return 0


def add_datagen_parser(subparsers: Any) -> None:
    """Add the ``datagen`` subcommand to the ``diathermy`` parser's subparsers."""
    s = subparsers.add_parser(
        "datagen", help="generate the surrogate training dataset (Algorithm 1) into HDF5"
    )
    s.add_argument("config", help="datagen config, JSON or YAML (fields of DatagenConfig)")
    s.add_argument("--out", required=True, help="dataset file to write, e.g. data.h5")
    s.add_argument("--workers", type=_positive_int, help="worker processes (default: config)")
    s.add_argument("--engine", choices=ENGINES, default="local", help="local processes or dask")
    s.add_argument("--scheduler", help="address of an existing Dask scheduler (--engine dask)")
    s.add_argument("--scenarios", type=_positive_int, help="override n_scenarios")
    s.add_argument("--resume", action="store_true", help="continue an interrupted dataset file")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_datagen)
