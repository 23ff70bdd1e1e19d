"""The ``diathermy`` command line: simulate scenes, list them, print their schema.

Every user error prints one line (``diathermy: error: ...``) and exits with status 2; a
traceback means a bug.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from diathermy.errors import DiathermyError
from diathermy.runtime import configure_threads
from diathermy.scene import (
    builtin_scene,
    builtin_scene_names,
    parse_grid,
    resolve_scene,
    scene_from_dict,
    scene_json_schema,
)
from diathermy.version import __version__


def _cmd_simulate(args: argparse.Namespace) -> int:
    from diathermy.engine.run import run_scene  # heavy imports only when simulating
    from diathermy.report.budget import resolve_accuracy_budget
    from diathermy.worker.registry import RegistryModels

    data = resolve_scene(args.scene).model_dump()
    if args.grid is not None:  # a uniform grid: it replaces a graded scene's resolution
        data["grid"] = args.grid
        data["resolution"] = None
    if args.steps is not None:
        data["steps"] = args.steps
    if args.mechanics is not None:
        data["mechanics"]["backend"] = args.mechanics
    if args.model is not None:
        data["mechanics"]["model"] = args.model
    if args.guard is not None:
        data["mechanics"]["guard_tolerance"] = args.guard
    if args.correction is not None:
        data["mechanics"]["correction"] = args.correction
    scene = resolve_accuracy_budget(
        scene_from_dict(data), os.environ.get("DIATHERMY_ACCURACY_REPORT")
    )
    summary = run_scene(
        scene,
        models=RegistryModels(os.environ.get("DIATHERMY_DATA_DIR", "diathermy-data")),
        out=Path(args.out),
        vtu_dir=Path(args.vtu) if args.vtu else None,
        every=args.every,
        progress=not args.quiet,
    )
    print(summary)
    for warning in summary.warnings():
        print(warning, file=sys.stderr)
    return 0


def _cmd_scenes(args: argparse.Namespace) -> int:
    for name in builtin_scene_names():
        s = builtin_scene(name)
        nz, ny, nx = s.node_shape
        kind = "graded" if s.resolution is not None else "uniform"
        print(
            f"{name:18s} {nz}x{ny}x{nx} {kind}  {s.steps:4d} steps  {', '.join(s.closed_effects)}"
        )
        if args.verbose:
            print(f"    {s.description}")
    return 0


def _cmd_schema(args: argparse.Namespace) -> int:
    text = json.dumps(scene_json_schema(), indent=2)
    if args.out:
        Path(args.out).write_text(text + "\n", encoding="utf-8")
    else:
        print(text)
    return 0


def _cmd_show_scene(args: argparse.Namespace) -> int:
    print(resolve_scene(args.scene).model_dump_json(indent=2))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="diathermy", description="Electrosurgery simulator.")
    p.add_argument("--version", action="version", version=f"diathermy {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("simulate", help="run a scene and write an HDF5 run file")
    s.add_argument(
        "scene",
        nargs="?",
        help="built-in scene name or JSON/YAML file (default: the default scene)",
    )
    s.add_argument(
        "--grid",
        type=parse_grid,
        help="a uniform grid of NZxNYxNX nodes (replaces the scene's grid and resolution)",
    )
    s.add_argument("--steps", type=int, help="override the number of steps")
    s.add_argument("--out", default="runs/run.h5", help="run file to write (default runs/run.h5)")
    s.add_argument(
        "--vtu", help="also write ParaView VTU files (and a .pvd series) into this folder"
    )
    s.add_argument("--every", type=int, default=1, help="write every k-th step (default 1)")
    s.add_argument("--mechanics", choices=["fem", "cnn", "pgd"], help="mechanics backend")
    s.add_argument("--model", help="surrogate model file for --mechanics cnn|pgd")
    s.add_argument(
        "--guard", type=float, metavar="TOL",
        help="mechanics.guard_tolerance: cnn continues with CG while the relative residual "
        "exceeds it (the patch alone stays within 1 %% strain energy on the benchmark scenes, "
        "5e-3 takes it to ~0.1 %%: benchmarks/results/hybrid.md); pgd enriches a mode when its "
        "estimated strain-energy error does",
    )  # fmt: skip
    s.add_argument(
        "--correction", choices=["none", "patch"],
        help="mechanics.correction for --mechanics cnn: 'patch' (default) re-solves equilibrium "
        "where the prediction's residual concentrates; 'none' keeps the network's u",
    )  # fmt: skip
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_simulate)

    s = sub.add_parser("scenes", help="list the built-in scenes")
    s.add_argument("-v", "--verbose", action="store_true")
    s.set_defaults(func=_cmd_scenes)

    s = sub.add_parser(
        "show-scene", help="print a scene (built-in or file) as JSON with all defaults"
    )
    s.add_argument("scene", nargs="?")
    s.set_defaults(func=_cmd_show_scene)

    s = sub.add_parser("schema", help="print the scene JSON Schema")
    s.add_argument("--out", help="write to this file instead of stdout")
    s.set_defaults(func=_cmd_schema)

    from diathermy.surrogates.cli import add_evaluate_parser, add_train_parser  # no torch import

    add_train_parser(sub)
    add_evaluate_parser(sub)
    from diathermy.surrogates.pgd.cli import add_pgd_parser  # numpy/scipy only, no torch

    add_pgd_parser(sub)
    from diathermy.service.cli import add_serve_parser  # FastAPI itself loads only when serving

    add_serve_parser(sub)

    from diathermy.datagen.cli import add_datagen_parser

    add_datagen_parser(sub)
    from diathermy.report.cli import add_report_parser

    add_report_parser(sub)
    from diathermy.worker.cli import add_worker_parsers

    add_worker_parsers(sub)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "steps", None) is not None and args.steps < 0:
        parser.error("--steps must be >= 0")
    if getattr(args, "every", 1) < 1:
        parser.error("--every must be >= 1")
    configure_threads()
    try:
        return int(args.func(args))
    except DiathermyError as err:
        print(f"diathermy: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("diathermy: interrupted; what was written so far is kept", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
