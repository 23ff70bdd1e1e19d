"""A cheap closed-form stand-in for the FEM physics, to test the walk, storage and engines fast.

It honours the ScenarioPhysics contract: phi from the top surface, healthy = centroid phi > 0,
a displacement that depends on every input (pressure, phi, position) and a level set that
really cuts where the strain energy passes kappa, so walks meet removed tets.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from diathermy.datagen.config import DatagenConfig
from diathermy.mesh import TetMesh, build_tet_mesh


@lru_cache(maxsize=4)
def _mesh(config_json: str) -> TetMesh:
    return build_tet_mesh(DatagenConfig.model_validate_json(config_json).make_grid())


@dataclass(frozen=True)
class AnalyticPhysics:
    mesh: TetMesh
    p0_pa: float
    bulk_pa: float
    kappa_j_per_m3: float
    speed_m_per_s: float
    dt_s: float
    delay_s: float = 0.0

    def initial_level_set(self) -> np.ndarray:
        return self.mesh.grid.size_m[2] - self.mesh.points[:, 2]

    def healthy_tets(self, phi: np.ndarray) -> np.ndarray:
        return phi[self.mesh.tets].mean(axis=1) > 0

    def solve(self, pressure_pa: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.delay_s:
            time.sleep(self.delay_s)
        strain = (pressure_pa - self.p0_pa) / (3.0 * self.bulk_pa)
        healthy = np.where(phi > 0, 1.0, 1e3)  # removed tissue is soft: moves more
        u = strain[:, None] * healthy[:, None] * self.mesh.points
        w_node = 0.5 * (pressure_pa - self.p0_pa) ** 2 / self.bulk_pa
        return u, w_node[self.mesh.tets].mean(axis=1)

    def advance(self, phi: np.ndarray, strain_energy: np.ndarray, step: int) -> np.ndarray:
        node_w = np.zeros(self.mesh.n_nodes)
        np.maximum.at(node_w, self.mesh.tets.ravel(), np.repeat(strain_energy, 4))
        speed = self.speed_m_per_s * np.maximum(0.0, node_w / self.kappa_j_per_m3 - 1.0)
        return phi - speed * self.dt_s


def analytic_physics(config: DatagenConfig) -> AnalyticPhysics:
    m = config.material
    return AnalyticPhysics(
        mesh=_mesh(config.model_dump_json()),
        p0_pa=m.p_atm_pa,
        bulk_pa=m.bulk_modulus_pa,
        kappa_j_per_m3=1e-3 * m.damage_kappa_j_per_m3,  # cuts within a few steps
        speed_m_per_s=0.02,
        dt_s=config.dt_s,
        delay_s=float(os.environ.get("DIATHERMY_TEST_DELAY_S", "0")),
    )
