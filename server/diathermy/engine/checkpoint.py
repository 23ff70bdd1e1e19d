"""Checkpoints: a simulation's whole state in one HDF5 file, and back.

What is saved is what the next step reads: every field, the clock, the running energy totals, the
electrode overrides, the level-set re-initialisation counter, and the solver state that decides
the next iterates bit for bit (the cached unit-current potential and the Krylov warm start). AMG
hierarchies are not saved: the engine rebuilds them from the current operators, as the original
run does whenever an operator changes, so a restored run repeats the original exactly.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import h5py
import numpy as np
from pydantic import ValidationError

from diathermy.engine.electrodes import ElectrodeOverride
from diathermy.errors import CheckpointError
from diathermy.scene import Scene
from diathermy.version import __version__

if TYPE_CHECKING:
    from diathermy.engine.simulation import Simulation

CHECKPOINT_FORMAT = "diathermy-checkpoint"
CHECKPOINT_VERSION = 1


def save_checkpoint(sim: Simulation, path: str | Path) -> Path:
    """Write ``sim`` to ``path`` atomically (a temporary file renamed into place)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    st = sim.state
    with h5py.File(tmp, "w") as f:
        f.attrs.update(
            format=CHECKPOINT_FORMAT,
            format_version=CHECKPOINT_VERSION,
            diathermy_version=__version__,
            scene=sim.scene.model_dump_json(),
            step=st.step,
            time_s=st.time_s,
            energy_j=json.dumps(st.energy_j),
            overrides=json.dumps({k: asdict(v) for k, v in st.overrides.items()}),
            steps_since_reinit=sim._steps_since_reinit,
            mechanics_current=sim._last_mech_key is not None,
        )
        g = f.create_group("state")
        for name, arr in st.arrays.items():
            g.create_dataset(name, data=arr, compression="gzip", compression_opts=1)
        solver = f.create_group("solver")
        for name, arr in sim.solver_state().items():
            solver.create_dataset(name, data=arr)
    tmp.replace(path)
    return path


def load_checkpoint(path: str | Path) -> Simulation:
    """Rebuild a simulation from a checkpoint; corrupt or foreign files raise ``CheckpointError``."""
    from diathermy.engine.simulation import Simulation

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
            step, time_s = int(f.attrs["step"]), float(f.attrs["time_s"])
            energy = json.loads(f.attrs["energy_j"])
            overrides = {k: _override(v) for k, v in json.loads(f.attrs["overrides"]).items()}
            arrays = {k: v[()] for k, v in f["state"].items()}
            solver = {k: v[()] for k, v in f["solver"].items()}
            reinit = int(f.attrs["steps_since_reinit"])
            mech_current = bool(f.attrs["mechanics_current"])
        except (KeyError, ValueError, TypeError, OSError, ValidationError) as err:
            raise CheckpointError(
                f"{path}: checkpoint is incomplete or corrupt ({type(err).__name__}: {err})"
            ) from None
    sim = Simulation(scene)
    expected = {k: (v.shape, v.dtype) for k, v in sim.state.arrays.items()}
    got = {k: (v.shape, v.dtype) for k, v in arrays.items()}
    if expected != got:
        raise CheckpointError(
            f"{path}: fields do not match the scene's grid ({sorted(set(expected) ^ set(got)) or 'shapes differ'})"
        )
    for name, arr in arrays.items():
        if not np.all(np.isfinite(arr)) and arr.dtype != bool:
            raise CheckpointError(f"{path}: field {name} holds non-finite values")
    st = sim.state
    st.step, st.time_s, st.arrays, st.energy_j, st.overrides = (
        step,
        time_s,
        arrays,
        energy,
        overrides,
    )
    sim.restore_solver_state(solver, steps_since_reinit=reinit, mechanics_current=mech_current)
    return sim


def _override(d: dict[str, Any]) -> ElectrodeOverride:
    """An electrode override from its JSON form (lists back to tuples)."""
    pos = d.get("position_m")
    return ElectrodeOverride(
        position_m=None if pos is None else (float(pos[0]), float(pos[1])),
        power_w=d.get("power_w"),
        current_density_a_per_m2=d.get("current_density_a_per_m2"),
        active=d.get("active"),
    )
