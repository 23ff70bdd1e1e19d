"""Versioned CNN checkpoints: constructor args, weights and normaliser buffers, grid, metrics.

The file is a ``torch.save`` of plain dicts, lists, strings, numbers and tensors only, so it loads
with ``torch.load(weights_only=True)`` (no arbitrary code runs on load).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from diathermy.errors import CheckpointError
from diathermy.mesh.grid import Grid
from diathermy.surrogates.cnn import DisplacementCNN
from diathermy.version import __version__

FORMAT_NAME = "diathermy-cnn"
# 1: two input channels; 2: a model with the tissue-mask channel (``CNNConfig.mask_input``), which
# a reader of version 1 cannot build. Models without the mask are still written as version 1.
# 3: a U-Net body (``CNNConfig.arch`` "unet"). Each model is written with the lowest version
# that can read it: older readers refuse what they cannot build instead of misreading it.
FORMAT_VERSION = 3
READABLE_VERSIONS = (1, 2, 3)
_REQUIRED = ("constructor_args", "state_dict", "grid_shape", "spacing_m")


@dataclass(frozen=True)
class LoadedCheckpoint:
    """A model rebuilt from a checkpoint with everything the file said about it.

    ``training_state`` (epoch, last weights, optimizer state, early-stopping counters) is present
    only in checkpoints written by the trainer; it is what ``--resume`` continues from.
    """

    model: DisplacementCNN
    grid_shape: tuple[int, int, int]
    spacing_m: tuple[float, float, float]
    # node coordinates (x, y, z) in m of the graded grid the model was trained on; None: uniform
    axes_m: tuple[tuple[float, ...], ...] | None = None
    training_config: dict[str, Any] = field(default_factory=dict)
    metrics: dict[str, Any] = field(default_factory=dict)
    data: dict[str, Any] = field(default_factory=dict)
    training_state: dict[str, Any] | None = None


def format_version(model: DisplacementCNN) -> int:
    """The lowest checkpoint version whose readers can build ``model``."""
    if model.config.arch != "pooled":
        return 3
    return 2 if model.config.mask_input else 1


def save_checkpoint(
    path: str | os.PathLike[str],
    model: DisplacementCNN,
    *,
    grid_shape: tuple[int, int, int],
    spacing_m: tuple[float, float, float],
    training_config: dict[str, Any] | None = None,
    metrics: dict[str, Any] | None = None,
    data: dict[str, Any] | None = None,
    training_state: dict[str, Any] | None = None,
    axes_m: Sequence[Sequence[float]] | None = None,
) -> None:
    """Write ``model`` (on any device) atomically to ``path``; grid (nz, ny, nx), spacing (dx, dy,
    dz) m; ``axes_m``: the node coordinates (x, y, z) in m of a graded grid (its smallest cells
    as ``spacing_m``), which the model then applies to alone."""
    payload: dict[str, Any] = {
        "format": FORMAT_NAME,
        "format_version": format_version(model),
        "diathermy_version": __version__,
        "model": type(model).__name__,
        "constructor_args": model.constructor_args(),
        "state_dict": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
        "grid_shape": [int(n) for n in grid_shape],
        "spacing_m": [float(s) for s in spacing_m],
        "training_config": dict(training_config or {}),
        "metrics": dict(metrics or {}),
        "data": dict(data or {}),
    }
    if training_state is not None:
        payload["training_state"] = training_state
    if axes_m is not None:
        axes = [[float(v) for v in a] for a in axes_m]
        expected = [int(n) for n in grid_shape][::-1]  # (nx, ny, nz)
        if [len(a) for a in axes] != expected:
            raise CheckpointError(f"axes_m has {[len(a) for a in axes]} nodes, the grid {expected}")
        payload["axes_m"] = axes
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    torch.save(payload, tmp)
    os.replace(tmp, path)  # a crash mid-write never leaves a half checkpoint behind


def _read_payload(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise CheckpointError(f"model file {str(path)!r} does not exist")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # torch raises many types for garbage input
        raise CheckpointError(
            f"{str(path)!r} is not a readable diathermy CNN checkpoint (corrupt, truncated or "
            f"foreign file; {type(err).__name__})"
        ) from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT_NAME:
        raise CheckpointError(f"{str(path)!r} is not a diathermy CNN checkpoint (foreign file)")
    version = payload.get("format_version")
    if version not in READABLE_VERSIONS:
        readable = " and ".join(map(str, READABLE_VERSIONS))
        raise CheckpointError(
            f"{str(path)!r} has checkpoint format version {version!r}; this diathermy reads "
            f"versions {readable} (retrain or convert the model)"
        )
    missing = [k for k in _REQUIRED if k not in payload]
    if missing:
        raise CheckpointError(f"{str(path)!r} is a corrupt checkpoint: missing {missing}")
    return payload


def load_checkpoint(
    path: str | os.PathLike[str],
    *,
    expected_grid: tuple[int, int, int] | None = None,
    map_location: str | torch.device = "cpu",
) -> LoadedCheckpoint:
    """Read and validate a checkpoint; raises :class:`CheckpointError` with a one-line reason.

    ``expected_grid`` (nz, ny, nx): refuse a model trained for another grid.
    """
    path = Path(path)
    payload = _read_payload(path)
    grid = (*(int(n) for n in payload["grid_shape"]),)
    if len(grid) != 3:
        raise CheckpointError(f"{str(path)!r} is a corrupt checkpoint: grid_shape {grid}")
    if expected_grid is not None and grid != tuple(int(n) for n in expected_grid):
        g = "x".join(map(str, grid))
        e = "x".join(str(int(n)) for n in expected_grid)
        raise CheckpointError(
            f"model {str(path)!r} was trained for grid {g} (nodes z x y x x), the scene uses {e}"
        )
    try:
        model = DisplacementCNN.from_constructor_args(payload["constructor_args"])
        model.load_state_dict(payload["state_dict"], strict=True)
    except (KeyError, TypeError, ValueError, RuntimeError) as err:
        reason = str(err).strip().splitlines()[0][:200]
        raise CheckpointError(f"{str(path)!r} is a corrupt checkpoint: {reason}") from None
    model.to(map_location).eval()
    return LoadedCheckpoint(
        model=model,
        grid_shape=grid,
        spacing_m=tuple(float(s) for s in payload["spacing_m"]),  # type: ignore[arg-type]
        training_config=dict(payload.get("training_config") or {}),
        metrics=dict(payload.get("metrics") or {}),
        data=dict(payload.get("data") or {}),
        training_state=payload.get("training_state"),
        axes_m=_axes(path, payload.get("axes_m"), grid),
    )


def _axes(path: Path, raw: Any, grid: tuple[int, int, int]) -> tuple[tuple[float, ...], ...] | None:
    if raw is None:
        return None
    try:
        axes = tuple(tuple(float(v) for v in a) for a in raw)
    except (TypeError, ValueError):
        raise CheckpointError(f"{str(path)!r} is a corrupt checkpoint: axes_m") from None
    if [len(a) for a in axes] != list(grid[::-1]):
        raise CheckpointError(
            f"{str(path)!r} is a corrupt checkpoint: axes_m does not fit its grid"
        )
    return axes


def grid_mismatch(ckpt: LoadedCheckpoint, grid: Grid, name: str) -> str | None:
    """Why the model of ``ckpt`` (file ``name``) does not apply to ``grid`` (same node counts
    already checked), or None when it does: a uniform model needs the grid's spacing, a graded
    one the grid's node coordinates (to 1 um)."""
    if ckpt.axes_m is None:
        if not grid.is_uniform:
            return f"model {name!r} was trained for a uniform grid, the scene's grid is graded"
        if not np.allclose(ckpt.spacing_m, grid.spacing_m, rtol=1e-6, atol=0.0):
            return (
                f"model {name!r} was trained for node spacing {ckpt.spacing_m} m, the scene's "
                f"grid has {grid.spacing_m} m (another block size)"
            )
        return None
    for axis, trained, here in zip("xyz", ckpt.axes_m, grid.axes(), strict=True):
        if not np.allclose(trained, here, rtol=0.0, atol=1e-6):
            return (
                f"model {name!r} was trained for other {axis} node coordinates (a graded grid of "
                "another block, working region or resolution)"
            )
    return None
