"""A network beside persistence on a dataset (issue #22): every surrogate figure stands against
the obvious predictor, the previous sample of the same scenario.

Per sample, on the FEM system of its own (pressure, level set): the network's u and the previous
sample's u, each Ritz-scaled ('cnn', 'previous') and patch-corrected ('cnn+patch',
'previous+patch'), scored by the strain-energy error against the sample's u and timed
(``physics.predictor_errors``). A scenario's first sample has no previous: it is scored for the
network only, and every summary says over how many samples it ran.
"""

from __future__ import annotations

import os
import statistics
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from diathermy.mesh import Grid, build_tet_mesh
from diathermy.physics.mechanics_backend import FEMBackend
from diathermy.physics.patch_correction import node_graph
from diathermy.physics.predictor_errors import Score, StepSystem, score_start
from diathermy.physics.strain_energy import strain_energy_density
from diathermy.physics.strain_energy_error import dataset_tissue, tet_youngs_modulus
from diathermy.physics.topology import healthy_tets
from diathermy.surrogates.cnn import DisplacementCNN
from diathermy.surrogates.data import read_dataset_info, read_samples
from diathermy.surrogates.inference import predict

NAMES = ("cnn", "cnn+patch", "previous", "previous+patch")


@dataclass
class BaselineReport:
    """Scores per predictor name (``NAMES``), one per sample it ran on."""

    scores: dict[str, list[Score]] = field(default_factory=lambda: {n: [] for n in NAMES})

    def summary(self) -> dict[str, dict[str, float]]:
        """Per name: samples, mean and max strain-energy error, median cost in s."""
        out = {}
        for name, s in self.scores.items():
            e = [x.error for x in s]
            out[name] = {
                "samples": float(len(s)),
                "mean_strain_energy_error": float(np.mean(e)) if e else float("nan"),
                "max_strain_energy_error": float(np.max(e)) if e else float("nan"),
                "median_cost_s": statistics.median(x.cost_s for x in s) if s else float("nan"),
            }
        return out


def _network_u(model: DisplacementCNN, p: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """The network's u (n_nodes, 3) m of one sample's p (nz, ny, nx) Pa and phi m."""
    return predict(model, p, phi).reshape(-1, 3)


def baseline_report(
    model: DisplacementCNN,
    data_path: str | os.PathLike[str],
    *,
    scenarios: tuple[int, ...] | None = None,
) -> BaselineReport:
    """The network and persistence, alone and patched, on every sample of ``scenarios``."""
    info = read_dataset_info(data_path)
    chosen = info.complete_scenarios() if scenarios is None else scenarios
    tissue = dataset_tissue(info.material)
    nz, ny, nx = info.grid_shape
    dx, dy, dz = info.spacing_m
    mesh = build_tet_mesh(Grid((nz, ny, nx), size_m=(dx * (nx - 1), dy * (ny - 1), dz * (nz - 1))))
    fem = FEMBackend(
        mesh, poisson_ratio=tissue.poisson_ratio, p0_pa=tissue.p_atm_pa, rtol=1e-6,
        ersatz_ratio=tissue.ersatz_stiffness_ratio,
    )  # fmt: skip
    grads = fem.assembler.geom.grads
    graph = None
    report = BaselineReport()
    model.eval()
    for scenario in chosen:
        u_prev: np.ndarray | None = None
        for row in info.sample_indices((scenario,)):
            p, phi, u = read_samples(info.path, np.array([row]))
            p_n, phi_n = p[0].reshape(-1).astype(float), phi[0].reshape(-1).astype(float)
            u_ref = u[0].reshape(-1, 3).astype(float)
            E = tet_youngs_modulus(phi_n, mesh, tissue)
            solver, _ = fem.operator_for(E, healthy_tets(phi_n, mesh))
            graph = node_graph(solver.K) if graph is None else graph
            system = StepSystem.of(solver, p_n, tissue.p_atm_pa, graph)

            def W(x: np.ndarray, E: np.ndarray = E) -> np.ndarray:
                return strain_energy_density(grads, mesh.tets, x, E, tissue.poisson_ratio)

            W_ref = W(u_ref)
            if not W_ref.any():  # at rest: no relative error to speak of
                u_prev = u_ref
                continue
            net_u = partial(_network_u, model, p[0], phi[0])
            for s in score_start(system, "cnn", net_u, W, W_ref):
                report.scores[s.name].append(s)
            if u_prev is not None:
                for s in score_start(system, "previous", partial(np.array, u_prev), W, W_ref):
                    report.scores[s.name].append(s)
            u_prev = u_ref
    return report
