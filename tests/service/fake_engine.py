"""A fast stand-in for the engine's Simulation with the same contract (for service tests only).

Physics here is deliberately trivial but observable: each active electrode heats a Gaussian spot
on the top surface with its power, so 'power 0' shows as zero delivered power and no heating.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import h5py
import meshio
import numpy as np

from diathermy.engine.electrodes import ElectrodeOverride, electrode_pose
from diathermy.engine.report import EffectReport, StepReport
from diathermy.errors import CheckpointError, SceneError
from diathermy.mesh import Grid
from diathermy.scene import Scene, scene_from_dict

NODAL = ("potential", "temperature", "pressure", "vapor_fraction", "level_set", "thermal_damage")


class FakeSimulation:
    step_delay_s = 0.0  # tests raise it to make steps slow

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        lx, ly, lz = scene.block_m
        self.grid = Grid(tuple(scene.grid), size_m=(lx, ly, lz))
        self.step_index = 0
        self.time_s = 0.0
        self.last_report: StepReport | None = None
        self.effects = scene.closed_effects
        self.overrides: dict[str, dict[str, Any]] = {}
        self.temperature = np.full(self.grid.shape, 310.0)

    def dof_counts(self) -> dict[str, int]:
        n = self.grid.n_nodes
        return {"electric": n, "thermal": n, "mechanics": 3 * n}

    def field_names(self) -> list[str]:
        return [*NODAL, "displacement", "joule_heat", "strain_energy"]

    def _spot(self, x: float, y: float) -> np.ndarray:
        z, yy, xx = np.meshgrid(
            *[
                np.linspace(0, s, n)
                for s, n in zip(self.grid.size_m[::-1], self.grid.shape, strict=True)
            ],
            indexing="ij",
        )
        lz = self.grid.size_m[2]
        return np.exp(-((xx - x) ** 2 + (yy - y) ** 2 + (z - lz) ** 2) / (0.01**2))

    def set_electrode(self, name: str, **changes: Any) -> None:
        if name not in {e.name for e in self.scene.electrodes}:
            raise SceneError(f"name: unknown electrode {name!r}")
        pos = changes.get("position_m")
        lx, ly, _ = self.scene.block_m
        if pos is not None and not (0 <= pos[0] <= lx and 0 <= pos[1] <= ly):
            raise SceneError(f"position_m: ({pos[0]}, {pos[1]}) lies off the top surface")
        self.overrides.setdefault(name, {}).update(
            {k: v for k, v in changes.items() if v is not None}
        )

    def step(self) -> StepReport:
        t0 = time.perf_counter()
        if self.step_delay_s:
            time.sleep(self.step_delay_s)
        dt = self.scene.dt_s
        power = 0.0
        for el in self.scene.electrodes:
            o = ElectrodeOverride(**self.overrides.get(el.name, {}))
            pose = electrode_pose(el, self.time_s + dt / 2, o)
            if pose.active:
                power += pose.power_w
                self.temperature += 20 * dt * pose.power_w * self._spot(*pose.position_m)
        self.step_index += 1
        self.time_s += dt
        wall = time.perf_counter() - t0
        self.last_report = StepReport(
            step=self.step_index,
            time_s=self.time_s,
            effects={
                e: EffectReport(ran=True, wall_s=wall / len(self.effects)) for e in self.effects
            },
            wall_s=wall,
            delivered_power_w=power,
            max_temperature_k=float(self.temperature.max()),
        )
        return self.last_report

    def run(self, n: int) -> list[StepReport]:
        return [self.step() for _ in range(n)]

    def field(self, name: str) -> np.ndarray:
        shape = self.grid.shape
        n_tets = 6 * self.grid.n_cells
        if name == "temperature":
            return self.temperature.copy()
        if name == "level_set":
            return 373.0 - self.temperature
        if name in NODAL:
            return np.zeros(shape)
        if name == "displacement":
            return np.zeros((*shape, 3))
        if name in ("joule_heat", "strain_energy"):
            return np.zeros(n_tets)
        raise SceneError(f"unknown field {name!r}")

    def cut_surface(self) -> tuple[np.ndarray, np.ndarray]:
        if self.temperature.max() < 373.0:
            return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
        x, y = self.scene.electrodes[0].position_m
        lz = self.grid.size_m[2]
        v = np.array(
            [[x, y, lz - 0.005], [x + 0.003, y, lz], [x, y + 0.003, lz], [x - 0.003, y, lz]]
        )
        return v, np.array([[0, 1, 2], [0, 2, 3]])

    def save_checkpoint(self, path: str | Path) -> None:
        with h5py.File(path, "w") as f:
            f.attrs["scene"] = self.scene.model_dump_json()
            f.attrs["step"] = self.step_index
            f.attrs["time_s"] = self.time_s
            f.attrs["overrides"] = json.dumps(self.overrides)
            f["temperature"] = self.temperature

    @classmethod
    def load_checkpoint(cls, path: str | Path) -> FakeSimulation:
        try:
            with h5py.File(path, "r") as f:
                sim = cls(scene_from_dict(json.loads(f.attrs["scene"])))
                sim.step_index = int(f.attrs["step"])
                sim.time_s = float(f.attrs["time_s"])
                sim.overrides = json.loads(f.attrs["overrides"])
                sim.temperature = f["temperature"][()]
        except (OSError, KeyError) as err:
            raise CheckpointError(f"cannot read checkpoint {path}: {err}") from None
        return sim

    def write_vtu(self, path: str | Path) -> None:
        g = self.grid
        z, y, x = np.meshgrid(
            *[np.linspace(0, s, n) for s, n in zip(g.size_m[::-1], g.shape, strict=True)],
            indexing="ij",
        )
        pts = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
        cells = [("vertex", np.arange(len(pts))[:, None])]
        meshio.write(
            str(path), meshio.Mesh(pts, cells, point_data={"temperature": self.temperature.ravel()})
        )


class FakeEngine:
    def create(self, scene: Scene) -> FakeSimulation:
        return FakeSimulation(scene)

    def load(self, path: Path) -> FakeSimulation:
        return FakeSimulation.load_checkpoint(path)
