"""``diathermy report accuracy-cost``: measure every accuracy knob of the scenes, side by side."""

from __future__ import annotations

import argparse
import dataclasses
import shutil
import sys
from pathlib import Path
from typing import Any

from diathermy.errors import SceneError


def _models(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        name, sep, path = item.partition("=")
        if not sep or not name or not path:
            raise SceneError(
                f"--model takes NAME=PATH (NAME starting with cnn or pgd), got {item!r}"
            )
        if not name.startswith(("cnn", "pgd")):
            raise SceneError(f"--model {item!r}: NAME must start with 'cnn' or 'pgd'")
        if not Path(path).exists():
            raise SceneError(f"--model {item!r}: no such file {path}")
        out[name] = path
    return out


def _cmd(args: argparse.Namespace) -> int:
    from diathermy.report.accuracy_cost import accuracy_cost_report
    from diathermy.report.budget import PACKAGED_REPORT
    from diathermy.report.variants import default_variants
    from diathermy.scene import parse_grid, resolve_scene

    scenes = [resolve_scene(s) for s in args.scenes.split(",")]
    if args.grid:
        g = parse_grid(args.grid)
        scenes = [s.on_uniform_grid(g) for s in scenes]
    variants = default_variants(_models(args.model or []))
    if args.coarse_grid:
        cg = parse_grid(args.coarse_grid)
        variants = [dataclasses.replace(v, grid=cg) if v.grid else v for v in variants]
    if args.variants:
        wanted = set(args.variants.split(","))
        unknown = wanted - {v.name for v in variants}
        if unknown:
            raise SceneError(
                f"--variants: unknown {sorted(unknown)}; known: {[v.name for v in variants]}"
            )
        variants = [v for v in variants if v.name in wanted]
    out = Path(args.out)
    command = (
        "diathermy report accuracy-cost " + " ".join(sys.argv[3:]) if len(sys.argv) > 3 else None
    )
    rows = accuracy_cost_report(
        scenes, variants, steps=args.steps, out=out, progress=not args.quiet, command=command
    )
    print(f"{len(rows)} rows -> {out / 'report.md'}")
    if args.install:
        PACKAGED_REPORT.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(out / "report.json", PACKAGED_REPORT)
        print(f"installed as the packaged report: {PACKAGED_REPORT}")
    return 0


def add_report_parser(subparsers: Any) -> None:
    """Register ``diathermy report accuracy-cost``."""
    rep = subparsers.add_parser("report", help="reports measured from the product itself")
    sub = rep.add_subparsers(dest="report", required=True)
    s = sub.add_parser(
        "accuracy-cost", help="time per step vs error of every solver knob, side by side"
    )
    s.add_argument(
        "--scenes",
        default="fixed-electrode,moving-electrode-slow",
        help="comma-separated scene names or files",
    )
    s.add_argument(
        "--grid",
        default="33x33x65",
        help="the uniform grid (NZxNYxNX) the scenes run on (default 33x33x65, the shipped "
        "surrogates'; the report compares uniform grids)",
    )
    s.add_argument(
        "--coarse-grid", default=None, help="grid of the coarse-grid variant (default 17x17x33)"
    )
    s.add_argument("--steps", type=int, default=80, help="steps per run (default 80)")
    s.add_argument(
        "--model",
        action="append",
        help="surrogate to include: cnn-w16=model.pt or pgd-15=model.npz",
    )
    s.add_argument("--variants", help="only these variants (comma-separated names)")
    s.add_argument("--out", default="benchmarks/results/accuracy-cost", help="output folder")
    s.add_argument(
        "--install",
        action="store_true",
        help="also make this the packaged report the accuracy budget uses",
    )
    s.add_argument("--quiet", action="store_true")
    s.set_defaults(func=_cmd)
