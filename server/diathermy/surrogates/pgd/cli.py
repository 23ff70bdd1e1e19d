"""``diathermy pgd-build CONFIG --out model.npz [--modes N]``: build a PGD model offline.

CONFIG (JSON or YAML) names the scene whose grid, block and material the model serves
(``scene``: built-in name or file; optional ``grid`` [nz, ny, nx] override) and the training
manifold (``manifold``: the fields of ``TrainingManifold``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from diathermy.errors import SceneError


def _modes(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value <= 50:
        raise argparse.ArgumentTypeError(f"--modes must be an integer in 1..50, got {text!r}")
    return value


def read_config(path: str | Path) -> dict[str, Any]:
    """The build config as a mapping; SceneError when missing or unreadable."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"PGD build config {str(path)!r} does not exist")
    text = path.read_text(encoding="utf-8")
    try:
        if path.suffix.lower() in {".yaml", ".yml"}:
            import yaml

            data = yaml.safe_load(text)
        else:
            data = json.loads(text)
    except Exception as err:  # noqa: BLE001 - any parse error is the user's file
        raise SceneError(f"PGD build config {str(path)!r} is not valid: {err}") from None
    if not isinstance(data, dict) or not isinstance(data.get("manifold"), dict):
        raise SceneError(f"PGD build config {str(path)!r} needs a 'manifold' mapping")
    return data


def _cmd_pgd_build(args: argparse.Namespace) -> int:
    from diathermy.scene import resolve_scene
    from diathermy.surrogates.pgd.model import save_model
    from diathermy.surrogates.pgd.offline import TrainingManifold, build_model

    cfg = read_config(args.config)
    scene = resolve_scene(cfg.get("scene"))
    raw = [int(v) for v in cfg.get("grid", scene.grid)]
    if len(raw) != 3 or min(raw) < 3:
        raise SceneError(f"grid must be three node counts >= 3, got {raw}")
    grid = (raw[0], raw[1], raw[2])
    manifold_data = dict(cfg["manifold"])
    if args.modes is not None:
        manifold_data["n_modes"] = args.modes
    manifold = TrainingManifold.from_dict(manifold_data)
    if "grid" not in cfg and scene.resolution is not None:
        raise SceneError(
            f"scene {scene.name!r} is on a graded grid (resolution) and a PGD model lives on a "
            "uniform one: give the build config a 'grid' (nodes nz, ny, nx)"
        )
    model = build_model(
        manifold,
        grid,
        tuple(scene.block_m),  # type: ignore[arg-type]
        scene.material,
        progress=None if args.quiet else print,
    )
    out = save_model(model, args.out)
    info = model.build_info
    print(
        f"wrote {out}: {model.n_modes} modes, residual {model.residual_history[-1]:.3e}, "
        f"{info['snapshots']} snapshots ({info['snapshot_s']:.1f} s FEM, "
        f"{info['enrichment_s']:.1f} s enrichment)"
    )
    return 0


def add_pgd_parser(subparsers: Any) -> None:
    """Register ``pgd-build`` on the main CLI's subparsers."""
    s = subparsers.add_parser("pgd-build", help="build a hybrid-PGD mechanics model offline")
    s.add_argument("config", help="JSON/YAML build config (scene, optional grid, manifold)")
    s.add_argument("--out", required=True, help="model file to write (.npz)")
    s.add_argument("--modes", type=_modes, help="most modes to build, 1..50 (overrides config)")
    s.add_argument("--quiet", action="store_true", help="no progress lines")
    s.set_defaults(func=_cmd_pgd_build)
