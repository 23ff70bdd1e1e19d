"""Checkpoints: a simulation's whole state in one HDF5 file, and back.

What is saved is what the next step reads: every field, the clock, the energy ledger, the
electrode overrides, the level-set re-initialisation counter, and the solver state that decides
the next iterates bit for bit (the cached unit-current potential and the Krylov warm start). AMG
hierarchies are not saved but where they come from: the potential's and the FEM mechanics' are
kept across operator changes while they pay, so the checkpoint holds the conductivity and the
Young's modulus each was built for, with its reuse counters; a restore rebuilds them from those,
and a restored run repeats the original exactly.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from pydantic import ValidationError

from diathermy.engine.backends import fem_of
from diathermy.engine.contact import weights_of
from diathermy.engine.context import EngineContext
from diathermy.engine.effects.electric import conductivity
from diathermy.engine.effects.mechanics import load_key
from diathermy.engine.electrodes import ElectrodeOverride
from diathermy.engine.ledger import EnergyLedger
from diathermy.engine.removal import tissue_share
from diathermy.engine.state import SimulationState
from diathermy.errors import CheckpointError, MeshError, SceneError
from diathermy.fem.solvers import ReuseState
from diathermy.mesh.grid_attrs import grid_attrs, grid_from_attrs
from diathermy.physics.incremental_mechanics import IncrementalFEMBackend
from diathermy.physics.mechanics_backend import HierarchyOrigin
from diathermy.physics.topology import evaluate_topology
from diathermy.scene import Scene
from diathermy.version import __version__

CHECKPOINT_FORMAT = "diathermy-checkpoint"
CHECKPOINT_VERSION = 1


@dataclass(frozen=True)
class SavedRun:
    """The contents of a checkpoint file."""

    scene: Scene
    step: int
    time_s: float
    energy: EnergyLedger
    overrides: dict[str, ElectrodeOverride]
    arrays: dict[str, np.ndarray]
    solver: dict[str, np.ndarray]
    steps_since_reinit: int
    mechanics_current: bool


def save_checkpoint(
    path: str | Path, scene: Scene, state: SimulationState, solver: dict[str, np.ndarray]
) -> Path:
    """Write the state to ``path`` atomically (a temporary file renamed into place)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with h5py.File(tmp, "w") as f:
        f.attrs.update(
            format=CHECKPOINT_FORMAT,
            format_version=CHECKPOINT_VERSION,
            diathermy_version=__version__,
            scene=scene.model_dump_json(),
            step=state.step,
            time_s=state.time_s,
            energy_j=json.dumps(state.energy.totals()),
            overrides=json.dumps({k: asdict(v) for k, v in state.overrides.items()}),
            steps_since_reinit=state.memory.steps_since_reinit,
            mechanics_current=state.memory.mechanics_key is not None,
            **grid_attrs(scene.node_grid()),
        )
        g = f.create_group("state")
        for name, arr in state.arrays.items():
            g.create_dataset(name, data=arr, compression="gzip", compression_opts=1)
        group = f.create_group("solver")
        for name, arr in solver.items():
            group.create_dataset(name, data=arr)
    tmp.replace(path)
    return path


def read_checkpoint(path: str | Path) -> SavedRun:
    """Read a checkpoint; corrupt or foreign files raise ``CheckpointError``."""
    path = Path(path)
    try:
        f = h5py.File(path, "r")
    except (OSError, ValueError) as err:
        raise CheckpointError(f"{path} is not a readable HDF5 checkpoint: {err}") from None
    with f:
        if f.attrs.get("format") != CHECKPOINT_FORMAT:
            raise CheckpointError(f"{path} is not a diathermy checkpoint")
        version = int(f.attrs.get("format_version", -1))
        if version != CHECKPOINT_VERSION:
            raise CheckpointError(
                f"{path}: checkpoint format version {version} is not supported (expected {CHECKPOINT_VERSION})"
            )
        try:
            scene = Scene.model_validate_json(f.attrs["scene"])
            _check_grid(path, scene, f.attrs)
            return SavedRun(
                scene=scene,
                step=int(f.attrs["step"]),
                time_s=float(f.attrs["time_s"]),
                energy=EnergyLedger.from_totals(json.loads(f.attrs["energy_j"])),
                overrides={k: _override(v) for k, v in json.loads(f.attrs["overrides"]).items()},
                arrays={k: v[()] for k, v in f["state"].items()},
                solver={k: v[()] for k, v in f["solver"].items()},
                steps_since_reinit=int(f.attrs["steps_since_reinit"]),
                mechanics_current=bool(f.attrs["mechanics_current"]),
            )
        except CheckpointError:
            raise
        except (KeyError, ValueError, TypeError, OSError, ValidationError, MeshError) as err:
            raise CheckpointError(
                f"{path}: checkpoint is incomplete or corrupt ({type(err).__name__}: {err})"
            ) from None


def _check_grid(path: str | Path, scene: Scene, attrs: Any) -> None:
    """Raise ``CheckpointError`` when the saved node coordinates are not the scene's grid's."""
    if "grid_shape" not in attrs:  # written before the grid was saved: the scene decides
        return
    saved, grid = grid_from_attrs(attrs), scene.node_grid()
    if saved.shape != grid.shape or not all(
        np.allclose(a, b, rtol=0.0, atol=1e-12)
        for a, b in zip(saved.axes(), grid.axes(), strict=True)
    ):
        raise CheckpointError(
            f"{path}: the saved grid {saved.shape} is not the grid its scene builds {grid.shape}"
        )


def check_fields(
    path: str | Path, expected: dict[str, np.ndarray], got: dict[str, np.ndarray]
) -> None:
    """Raise ``CheckpointError`` unless the saved fields fit the scene's grid and are finite."""
    want = {k: (v.shape, v.dtype) for k, v in expected.items()}
    have = {k: (v.shape, v.dtype) for k, v in got.items()}
    if want != have:
        raise CheckpointError(
            f"{path}: fields do not match the scene's grid ({sorted(set(want) ^ set(have)) or 'shapes differ'})"
        )
    for name, arr in got.items():
        if not np.all(np.isfinite(arr)) and arr.dtype != bool:
            raise CheckpointError(f"{path}: field {name} holds non-finite values")


def solver_state(ctx: EngineContext) -> dict[str, np.ndarray]:
    """Solver data that decides the next iterates: the cached unit potential, warm starts."""
    out: dict[str, np.ndarray] = {}
    warm = ctx.potential.solver.krylov.warm_start
    if warm is not None:
        out["potential_warm_start"] = warm
    cached = ctx.potential.cached_unit_field()
    if cached is not None:
        contact, (V1, load1, R) = cached
        key = ctx.contacts.key_of(contact)
        if key is not None:
            out["potential_unit_V"], out["potential_unit_load"] = V1, load1
            out["potential_unit_R"] = np.asarray(R)
            out["potential_contact_key"] = np.asarray(key)
            # the conductivity V1 was solved with: the cut may have changed it since
            out["potential_sigma"] = np.asarray(ctx.potential.solver.sigma)
    out.update(_hierarchy_state(ctx))
    return out


def _hierarchy_state(ctx: EngineContext) -> dict[str, np.ndarray]:
    """The operators the kept AMG hierarchies were built for, and their reuse counters."""
    out: dict[str, np.ndarray] = {}
    solver = ctx.potential.solver
    if solver.hierarchy_sigma is not None:
        out["potential_hierarchy_sigma"] = np.asarray(solver.hierarchy_sigma)
        out["potential_hierarchy_reuse"] = _reuse_array(solver.krylov.reuse)
        out["potential_operator_sigma"] = np.asarray(solver.sigma)
    backend = ctx.built_mechanics
    if isinstance(backend, IncrementalFEMBackend):
        out["mechanics_since_full"] = np.asarray(backend.since_full)
        if backend.last_E_pa is not None:
            out["mechanics_last_E"] = backend.last_E_pa
        if backend.history:
            out["mechanics_history"] = np.stack(backend.history)
        if backend.window is not None:
            out["mechanics_window_box"] = backend.window.box.as_array()
            out["mechanics_window_E"] = backend.window.built_E
            out["mechanics_window_healthy"] = backend.window.built_healthy
    fem = fem_of(backend)
    origin = fem.hierarchy_origin if fem is not None else None
    if origin is not None:
        out["mechanics_hierarchy_E"] = origin.youngs_modulus_pa
        out["mechanics_hierarchy_healthy"] = origin.healthy
        out["mechanics_hierarchy_reuse"] = _reuse_array(origin.reuse)
    return out


def _reuse_array(r: ReuseState) -> np.ndarray:
    return np.array([r.fresh_rate, r.stale_solves, float(r.rebuild_due)])


def _reuse_state(a: np.ndarray) -> ReuseState:
    return ReuseState(float(a[0]), int(a[1]), bool(a[2]))


def _restore_hierarchies(ctx: EngineContext, solver: dict[str, np.ndarray]) -> None:
    """Rebuild the kept hierarchies from the operators a checkpoint says they were built for."""
    if "potential_hierarchy_sigma" in solver:
        ctx.potential.solver.restore_hierarchy(
            solver["potential_hierarchy_sigma"], _reuse_state(solver["potential_hierarchy_reuse"])
        )
        ctx.potential.solver.set_conductivity(solver["potential_operator_sigma"])
    backend = ctx.mechanics if ctx.has("mechanics") else None
    if isinstance(backend, IncrementalFEMBackend) and "mechanics_since_full" in solver:
        backend.since_full = int(solver["mechanics_since_full"])
        backend.last_E_pa = solver.get("mechanics_last_E")
        backend.windowed.window = None
        n_nodes = ctx.disc.mesh.n_nodes
        history = np.asarray(solver.get("mechanics_history", np.zeros((0, n_nodes, 3))))
        if (
            history.ndim != 3
            or history.shape[1:] != (n_nodes, 3)
            or not np.all(np.isfinite(history))
        ):
            raise CheckpointError(
                f"checkpoint's mechanics history: finite (m, {n_nodes}, 3) displacements "
                f"expected, got {history.shape}"
            )
        backend.history = [h.copy() for h in history[: backend.settings.window_history]]
        if "mechanics_window_box" in solver:
            box = np.asarray(solver["mechanics_window_box"])
            E = np.asarray(solver.get("mechanics_window_E", ()))
            healthy = np.asarray(solver.get("mechanics_window_healthy", ()))
            n_tets = ctx.disc.mesh.n_tets
            if box.shape != (4, 3) or E.shape != (n_tets,) or healthy.shape != (n_tets,):
                raise CheckpointError(
                    "checkpoint's mechanics window: a (4, 3) box and E and healthy per tet "
                    f"({n_tets}) expected, got {box.shape}, {E.shape}, {healthy.shape}"
                )
            backend.restore_window(box, E, healthy.astype(bool))
    fem = fem_of(backend)
    if "mechanics_hierarchy_E" in solver and fem is not None:
        fem.restore_hierarchy(
            HierarchyOrigin(
                solver["mechanics_hierarchy_E"],
                _healthy_or_share(solver["mechanics_hierarchy_healthy"]),
                _reuse_state(solver["mechanics_hierarchy_reuse"]),
            )
        )


def _healthy_or_share(saved: np.ndarray) -> np.ndarray:
    """The saved healthy mask, or the tissue shares a 'fraction' run saved (floats in [0, 1])."""
    return saved.astype(bool) if saved.dtype.kind in "biu" else saved.astype(float)


def restore_solver_state(
    ctx: EngineContext,
    state: SimulationState,
    solver: dict[str, np.ndarray],
    *,
    steps_since_reinit: int,
    mechanics_current: bool,
) -> None:
    """Put back what ``solver_state`` saved, so the next step repeats the original run."""
    memory = state.memory
    memory.steps_since_reinit = steps_since_reinit
    memory.topology = None
    if ctx.has("dissection") and (state["removed"].any() or state.step > 0):
        memory.topology = evaluate_topology(
            state["level_set"], ctx.disc.mesh, ctx.disc.geom.volumes
        )
    memory.mechanics_key = load_key(state, tissue_share(ctx, state)) if mechanics_current else None
    _restore_hierarchies(ctx, solver)
    if "potential_warm_start" in solver:
        ctx.potential.solver.krylov.warm_start = solver["potential_warm_start"]
    if "potential_unit_V" in solver:
        key = tuple(float(v) for v in np.ravel(solver["potential_contact_key"]))
        try:
            contact = weights_of(ctx.disc, key)
        except (SceneError, ValueError) as e:
            raise CheckpointError(f"checkpoint's contact disk is not valid: {e}") from e
        ctx.contacts.put(key, contact)
        memory.contacts = (key,)
        sigma = solver.get("potential_sigma")
        ctx.potential.solver.set_conductivity(conductivity(ctx, state) if sigma is None else sigma)
        ctx.potential.restore_unit_field(
            contact,
            (
                solver["potential_unit_V"],
                solver["potential_unit_load"],
                float(solver["potential_unit_R"]),
            ),
        )


def _override(d: dict[str, Any]) -> ElectrodeOverride:
    """An electrode override from its JSON form (lists back to tuples)."""
    pos = d.get("position_m")
    return ElectrodeOverride(
        position_m=None if pos is None else (float(pos[0]), float(pos[1])),
        power_w=d.get("power_w"),
        current_density_a_per_m2=d.get("current_density_a_per_m2"),
        active=d.get("active"),
        max_voltage_v=d.get("max_voltage_v"),  # absent in checkpoints before 2026-12-07
    )
