"""The mechanics backend a scene asks for: FEM, the hybrid CNN, or hybrid PGD.

Model files come from the scene (``mechanics.model``): a file path, else a name the caller's
``ModelResolver`` knows (the CLI and the service hand in their model registry); the engine
itself reads no registry, file or environment variable it was not handed.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Literal

from diathermy.engine.context import EngineContext
from diathermy.errors import DiathermyError, SceneError
from diathermy.fem.elastic import elastic_assembler
from diathermy.physics.incremental_mechanics import IncrementalFEMBackend
from diathermy.physics.local_solve import DEFAULT_GUARD_TOLERANCE, IncrementalSettings
from diathermy.physics.mechanics_backend import FEMBackend, MechanicsBackend
from diathermy.physics.predictors import DisplacementPredictor

ModelResolver = Callable[[str | None, tuple[int, int, int]], Path]
"""``(mechanics.model, grid) -> checkpoint``: a registry name (or None: the grid's default
model) to the CNN checkpoint file; raises ``SceneError`` naming ``mechanics.model``."""

PositionFn = Callable[[], "tuple[float, float] | None"]
"""The position (x, y) in m of the active electrode during the coming step, None when off."""


def shipped_models(model: str | None, grid: tuple[int, int, int]) -> Path:
    """The resolver without a registry: a file path as given, else the shipped model of the grid."""
    from diathermy.surrogates.backend import default_model_path

    if model is None:
        return default_model_path(grid)
    if Path(model).is_file():
        return Path(model)
    raise SceneError(
        f"mechanics.model: {model!r} is not a file, and no model registry was given to look "
        "the name up in (the CLI and the service use the one of their data directory)"
    )


def fem_of(backend: MechanicsBackend | None) -> FEMBackend | None:
    """The FEM backend that solves in full (the incremental one's, or the backend itself)."""
    if isinstance(backend, IncrementalFEMBackend):
        return backend.fem
    return backend if isinstance(backend, FEMBackend) else None


def auto_network(
    ctx: EngineContext, models: ModelResolver | None
) -> tuple[DisplacementPredictor | None, str | None]:
    """The network 'auto' may ask, or None and why not (no model for the grid, a model trained
    for another grid, one that does not load): 'auto' then runs on persistence, never fails
    mid-run. A graded grid takes a model trained on its own node coordinates."""
    grid = ctx.disc.grid
    shape = "x".join(str(n) for n in grid.shape)
    model = ctx.scene.mechanics.model
    try:
        # torch loads only here: an engine without a network never imports it
        from diathermy.surrogates.predictor import CNNPredictor

        path = Path(model) if model is not None and Path(model).is_file() else None
        if path is None:
            path = (models or shipped_models)(model, grid.shape)
        return CNNPredictor(ctx.disc.mesh, path), None
    except (DiathermyError, OSError, ImportError, RuntimeError, ValueError) as err:
        return None, f"no network for grid {shape} ({str(err).split(';')[0]}): persistence"


def guard_of(ctx: EngineContext) -> Literal["residual", "energy"]:
    """The local path's acceptance test: the scene's ``mechanics.guard``, where 'auto' is the
    energy estimate on graded grids unless a residual tolerance is set (the residual guard let
    57 % strain-energy errors through on the moving electrode's 1 mm grid, realtime.md)."""
    cfg = ctx.scene.mechanics
    if cfg.guard != "auto":
        return cfg.guard
    graded = not ctx.disc.grid.is_uniform
    return "energy" if graded and cfg.guard_tolerance is None else "residual"


def make_backend(
    ctx: EngineContext, *, models: ModelResolver | None, position: PositionFn
) -> MechanicsBackend:
    """The backend ``ctx.scene.mechanics`` asks for."""
    cfg, tissue = ctx.scene.mechanics, ctx.tissue
    if cfg.backend == "fem":
        disc = ctx.disc
        fem = FEMBackend(
            disc.mesh,
            poisson_ratio=tissue.poisson_ratio,
            p0_pa=tissue.p_atm_pa,
            rtol=cfg.rtol,
            ersatz_ratio=tissue.ersatz_stiffness_ratio,
            # the discretization's pattern and geometry: the backend's own build has the same
            # (a second copy: ~9 % of the engine's memory)
            assembler=elastic_assembler(disc.pattern, disc.geom, disc.mesh.shape_id),
        )
        if not ctx.scene.solver.incremental or cfg.predictor == "none":
            return fem
        settings = IncrementalSettings(
            guard_tolerance=cfg.guard_tolerance or DEFAULT_GUARD_TOLERANCE,
            full_every=cfg.full_every,
            patch_threshold=cfg.patch_threshold,
            patch_layers=cfg.patch_layers,
            patch=cfg.correction == "patch",
            guard=guard_of(ctx),
            energy_tolerance=cfg.energy_tolerance,
            polish_iterations=cfg.polish_iterations,
            window_m=cfg.polish_window_m,
            window_history=cfg.window_history,
            interval_tolerance=cfg.interval_tolerance,
        )
        if cfg.predictor != "auto":
            return IncrementalFEMBackend(fem, settings)
        network, unavailable = auto_network(ctx, models)
        return IncrementalFEMBackend(
            fem, settings, predictor="auto", network=network, network_unavailable=unavailable
        )
    if cfg.backend in ("cnn", "pgd") and not ctx.disc.grid.is_uniform:
        shape = "x".join(str(n) for n in ctx.disc.grid.shape)
        hint = (
            "mechanics.predictor 'auto' with a network trained for this grid"
            if cfg.backend == "cnn"
            else "drop scene.resolution"
        )
        raise SceneError(
            f"mechanics.backend: '{cfg.backend}' runs on uniform grids only and the scene's grid "
            f"is graded ({shape} nodes, scene.resolution); use mechanics.backend 'fem' (with "
            f"{hint})"
        )
    if cfg.backend == "cnn":
        # torch loads only here: an FEM-only engine never imports it
        from diathermy.surrogates.backend import CNNBackend

        model = cfg.model
        grid = ctx.disc.grid.shape
        path = Path(model) if model is not None and Path(model).is_file() else None
        if path is None:
            path = (models or shipped_models)(model, grid)
        return CNNBackend(
            ctx.disc.mesh,
            path,
            poisson_ratio=tissue.poisson_ratio,
            p0_pa=tissue.p_atm_pa,
            ersatz_ratio=tissue.ersatz_stiffness_ratio,
            guard_tolerance=cfg.guard_tolerance,
            correction=cfg.correction,
            patch_threshold=cfg.patch_threshold,
            patch_layers=cfg.patch_layers,
        )
    if cfg.backend == "pgd":
        from diathermy.surrogates.pgd.backend import PGDBackend
        from diathermy.surrogates.pgd.model import load_model

        if not cfg.model:
            raise SceneError(
                "mechanics.backend 'pgd' needs mechanics.model: a PGD model file "
                "(diathermy pgd-build)"
            )
        pgd = load_model(cfg.model, grid_shape=ctx.scene.grid, block_m=ctx.scene.block_m)
        return PGDBackend(
            pgd,
            ctx.disc.mesh,
            ctx.disc.grid,
            enrich_tol=cfg.guard_tolerance,
            position_fn=position,
            rtol=cfg.rtol,
        )
    raise SceneError(f"mechanics.backend: unknown backend {cfg.backend!r}")
