"""Run one variant of a scene in a fresh process and record what the accuracy-cost report needs."""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import h5py
import numpy as np

from diathermy.report.variants import Variant
from diathermy.scene import Scene


@dataclass
class RunRecord:
    """Costs and scalar outcomes of one variant run (the fields live in its HDF5 file)."""

    scene: str
    variant: Variant
    key: str
    steps: int
    grid: tuple[int, int, int]
    step_s: list[float] = field(default_factory=list)
    effect_s: dict[str, list[float]] = field(default_factory=dict)
    mechanics_iterations: list[int] = field(default_factory=list)
    cut_volume_m3: list[float] = field(default_factory=list)
    crater_depth_m: list[float] = field(default_factory=list)
    time_s: list[float] = field(default_factory=list)
    peak_rss_mb: float = 0.0
    build_s: float = 0.0
    error: str | None = None

    def to_json(self) -> str:
        d = asdict(self)
        return json.dumps(d)

    @staticmethod
    def from_json(text: str) -> RunRecord:
        d = json.loads(text)
        d["variant"] = Variant(
            **{
                **d["variant"],
                "grid": tuple(d["variant"]["grid"]) if d["variant"]["grid"] else None,
            }
        )
        d["grid"] = tuple(d["grid"])
        return RunRecord(**d)


def run_variant(scene_json: str, variant: Variant, steps: int, key: str, fields_path: str) -> str:
    """Entry point of the child process: run, write W and u per step, return the record as JSON."""
    from diathermy.engine.simulation import Simulation
    from diathermy.runtime import configure_threads, own_peak_rss_mib

    configure_threads()
    scene = variant.apply(Scene.model_validate_json(scene_json), steps)
    rec = RunRecord(scene=scene.name, variant=variant, key=key, steps=steps, grid=scene.grid)
    try:
        t0 = time.perf_counter()
        sim = Simulation(scene)
        rec.build_s = time.perf_counter() - t0
        n_tets, n_nodes = sim.disc.n_tets, sim.disc.n_nodes
        with h5py.File(fields_path, "w") as f:
            W = f.create_dataset(
                "strain_energy",
                (steps, n_tets),
                "f4",
                chunks=(1, n_tets),
                compression="gzip",
                compression_opts=1,
            )
            U = f.create_dataset(
                "displacement",
                (steps, n_nodes, 3),
                "f4",
                chunks=(1, n_nodes, 3),
                compression="gzip",
                compression_opts=1,
            )
            for i in range(steps):
                r = sim.step()
                rec.step_s.append(r.wall_s)
                for name, er in r.effects.items():
                    rec.effect_s.setdefault(name, []).append(er.wall_s)
                mech = r.effects.get("mechanics")
                rec.mechanics_iterations.append(mech.iterations if mech else 0)
                rec.cut_volume_m3.append(r.cut_volume_m3)
                rec.crater_depth_m.append(r.crater_depth_m)
                rec.time_s.append(r.time_s)
                W[i] = sim.state["strain_energy"]
                U[i] = sim.state["displacement"]
    except Exception as err:  # recorded, so one failing variant does not sink the report
        rec.error = f"{type(err).__name__}: {err}"
    rec.peak_rss_mb = own_peak_rss_mib()
    return rec.to_json()


def load_fields(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(W (steps, n_tets), u (steps, n_nodes, 3)) of a recorded run."""
    with h5py.File(path, "r") as f:
        return f["strain_energy"][()], f["displacement"][()]
