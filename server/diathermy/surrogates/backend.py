"""The hybrid-CNN mechanics backend: the CNN predicts u from (p, phi); the FEM operator checks it.

Every step the prediction is scaled by its energy-optimal (Ritz) factor and its relative
equilibrium residual ||f - K u|| / ||f|| (free DOFs, one mat-vec with the FEM stiffness of the
current topology, assembled again only when E changes) is reported. By default a patch
correction then solves equilibrium exactly on the few hundred nodes where that residual
concentrates (the crater wall), the prediction held fixed around them. When a guard tolerance
is set and the residual still exceeds it, warm-started preconditioned CG on the FEM system
continues until the residual is below the tolerance (``physics.equilibrium_guard``).
The model runs on the GPU when there is one, else on the CPU, in inference mode, with its input
buffer reused across steps.
"""

from __future__ import annotations

import os
import time
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch

from diathermy.errors import CheckpointError, SceneError
from diathermy.fem.elastic import ElasticAssembler, eigenstress_load
from diathermy.fem.geometry import structured_geometry
from diathermy.mesh import TetMesh
from diathermy.physics.constraints import clamped_bottom
from diathermy.physics.equilibrium_guard import (
    GuardPreconditioner,
    GuardPreconditioners,
    correct,
    jacobi_cg,
    relative_residual,
    ritz_scale,
)
from diathermy.physics.mechanics import MechanicsSolver
from diathermy.physics.mechanics_backend import FEMBackend, MechanicsOutput
from diathermy.physics.patch_correction import node_graph, patch_correct, residual_patch
from diathermy.surrogates.checkpoint import grid_mismatch, load_checkpoint
from diathermy.surrogates.inference import default_device

MODELS_PACKAGE = "diathermy.surrogates.models"

Correction = Literal["none", "patch"]


def default_model_path(grid_shape: tuple[int, int, int]) -> Path:
    """The model shipped for grid (nz, ny, nx): ``models/cnn_<nz>x<ny>x<nx>.pt``.

    Raises ``SceneError`` naming the grids that have one when this grid has none.
    """
    name = "cnn_{}x{}x{}.pt".format(*(int(n) for n in grid_shape))
    folder = resources.files(MODELS_PACKAGE)
    path = Path(str(folder.joinpath(name)))
    if not path.is_file():
        shipped = sorted(p.name for p in Path(str(folder)).glob("cnn_*.pt"))
        grids = ", ".join(n.removeprefix("cnn_").removesuffix(".pt") for n in shipped) or "none"
        g = "x".join(str(int(n)) for n in grid_shape)
        raise SceneError(
            f"mechanics.model: no shipped CNN for grid {g} (shipped grids: {grids}); "
            f"train one (scripts/train_default_model.sh) and pass it as mechanics.model"
        )
    return path


class CNNBackend:
    """``MechanicsBackend`` by the CNN surrogate, with an optional equilibrium guard.

    Args:
        mesh: the scene's tet mesh (its grid must be the model's).
        model_path: checkpoint written by ``diathermy train``.
        poisson_ratio, p0_pa, ersatz_ratio: the material, as for ``FEMBackend``.
        guard_tolerance: correct predictions whose relative residual exceeds it; None reports
            the residual only.
        guard_maxiter: CG iteration cap of one correction.
        guard_preconditioner: "jacobi" (default: CG on the assembled K, no setup, measured
            cheaper at 33x33x65 than "amg", whose hierarchy is set up again per topology).
        device: torch device; default the GPU when there is one.
        ritz: scale the prediction by the energy-optimal factor (u.f)/(u.K u) (``ritz_scale``),
            free given the residual's mat-vec; the network fixes the shape, FEM the amplitude.
        correction: "patch" (default) re-solves equilibrium on the nodes whose residual force
            reaches ``patch_threshold`` x its peak, grown by ``patch_layers`` rings of
            neighbours (at most ``patch_max_nodes``), u held fixed outside; "none" keeps the
            network's u (Ritz-scaled).
    """

    name = "cnn"

    def __init__(
        self,
        mesh: TetMesh,
        model_path: str | os.PathLike[str],
        *,
        poisson_ratio: float,
        p0_pa: float,
        ersatz_ratio: float,
        guard_tolerance: float | None = None,
        guard_maxiter: int = 200,
        guard_preconditioner: GuardPreconditioner = "jacobi",
        device: str | torch.device | None = None,
        assembler: ElasticAssembler | None = None,
        ritz: bool = True,
        correction: Correction = "patch",
        patch_threshold: float = 0.1,
        patch_layers: int = 2,
        patch_max_nodes: int = 4000,
    ) -> None:
        if guard_tolerance is not None and not guard_tolerance > 0:
            raise SceneError(f"mechanics.guard_tolerance: must be > 0, got {guard_tolerance}")
        if correction not in ("none", "patch"):
            raise SceneError(f"mechanics.correction: 'none' or 'patch', got {correction!r}")
        if not 0.0 < patch_threshold <= 1.0:
            raise SceneError(f"mechanics.patch_threshold: must be in (0, 1], got {patch_threshold}")
        if patch_layers < 0:
            raise SceneError(f"mechanics.patch_layers: must be >= 0, got {patch_layers}")
        if patch_max_nodes < 1:
            raise SceneError(f"patch_max_nodes: must be >= 1, got {patch_max_nodes}")
        self.mesh = mesh
        self.model_path = Path(model_path)
        self.device = torch.device(device) if device is not None else default_device()
        grid = mesh.grid
        ckpt = load_checkpoint(self.model_path, expected_grid=grid.shape, map_location=self.device)
        mismatch = grid_mismatch(ckpt, grid, str(self.model_path))
        if mismatch is not None:
            raise CheckpointError(mismatch)
        self.model = ckpt.model.eval()
        self.metrics = ckpt.metrics
        self.poisson_ratio = float(poisson_ratio)
        self.p0_pa = float(p0_pa)
        self.ersatz_ratio = float(ersatz_ratio)
        self.guard_tolerance = guard_tolerance
        self.guard_maxiter = int(guard_maxiter)
        self.ritz = bool(ritz)
        self.correction: Correction = correction
        self.patch_threshold = float(patch_threshold)
        self.patch_layers = int(patch_layers)
        self.patch_max_nodes = int(patch_max_nodes)
        self._graph: Any = None
        # the FEM operator of the current topology (residual, Ritz scale, guard correction)
        self._fem = FEMBackend(
            mesh,
            poisson_ratio=self.poisson_ratio,
            p0_pa=self.p0_pa,
            rtol=min(guard_tolerance or 1e-6, 1e-6),
            ersatz_ratio=self.ersatz_ratio,
            assembler=assembler,
        )
        self._preconditioners = GuardPreconditioners(guard_preconditioner)
        self._geom = (
            assembler.geom
            if assembler is not None
            else structured_geometry(mesh.points, mesh.tets, mesh.shape_id)
        )
        self._free = ~clamped_bottom(mesh).mask(3 * mesh.n_nodes).reshape(-1, 3)
        self._K: Any = None
        self._K_E: np.ndarray | None = None
        self.n_predictions = 0
        self.n_corrections = 0

    @property
    def n_builds(self) -> int:
        """How many FEM operators (one per topology) the guard has built."""
        return self._fem.n_builds

    # ------------------------------------------------------------------ the network
    def predict(self, pressure_pa: np.ndarray, level_set_m: np.ndarray) -> np.ndarray:
        """Nodal p (n_nodes,) Pa and phi (n_nodes,) m -> u (n_nodes, 3) m, clamped bottom held."""
        shape = self.mesh.grid.shape
        norm = self.model.normalizer
        with torch.inference_mode():
            p = torch.from_numpy(np.asarray(pressure_pa, np.float32).reshape(1, *shape))
            phi = torch.from_numpy(np.asarray(level_set_m, np.float32).reshape(1, *shape))
            p, phi = p.to(self.device), phi.to(self.device)
            y = norm.decode_displacement(self.model(norm.encode_inputs(p, phi)), p)[0]
            u = y.permute(1, 2, 3, 0).reshape(-1, 3).to("cpu", torch.float64).numpy()
        u = np.array(u)  # own the memory: torch may reuse it
        u[~self._free] = 0.0
        self.n_predictions += 1
        return u

    # ------------------------------------------------------------------ the FEM operator
    def _stiffness(self, youngs_modulus_pa: np.ndarray) -> Any:
        """The assembled (unconstrained) stiffness of this E, kept until E changes."""
        if self._K is None or self._K_E is None or not np.array_equal(self._K_E, youngs_modulus_pa):
            self._K = self._fem.assembler.stiffness(youngs_modulus_pa, self.poisson_ratio)
            self._K_E = youngs_modulus_pa.copy()
        return self._K

    def operator_for(
        self, youngs_modulus_pa: np.ndarray, healthy: np.ndarray
    ) -> tuple[MechanicsSolver, bool]:
        """The FEM solver of this topology, rebuilt only when E changed; (solver, rebuilt)."""
        return self._fem.operator_for(youngs_modulus_pa, healthy)

    # ------------------------------------------------------------------ MechanicsBackend
    def solve(
        self,
        *,
        pressure_pa: np.ndarray,
        level_set_m: np.ndarray,
        youngs_modulus_pa: np.ndarray,
        healthy: np.ndarray,
        warm_start: np.ndarray | None,
    ) -> MechanicsOutput:
        """Predict u, measure its residual, correct it when the guard says so."""
        t0 = time.perf_counter()
        u = self.predict(pressure_pa, level_set_m)
        t1 = time.perf_counter()
        n = self.mesh.n_nodes
        dp = np.asarray(pressure_pa, float) - self.p0_pa
        f = eigenstress_load(self._geom, self.mesh.tets, n, dp, healthy)
        K = self._stiffness(youngs_modulus_pa)
        Ku = (K @ u.ravel()).reshape(-1, 3)
        alpha = 1.0
        if self.ritz:
            # u and K u are linear in the prediction: rescale both, no second mat-vec
            alpha = ritz_scale(f, Ku, u, self._free)
            u *= alpha
            Ku *= alpha
        before = after = relative_residual(f, Ku, self._free)
        t2 = time.perf_counter()
        extra: dict[str, float | int | bool | str] = {
            "cnn_s": t1 - t0,
            "residual_s": t2 - t1,
            "residual_before": before,
            "guard_tolerance": self.guard_tolerance if self.guard_tolerance is not None else 0.0,
            "guard_iterations": 0,
            "corrected": False,
            "ritz_scale": alpha,
            "device": self.device.type,
            "correction": self.correction,
            "patch_nodes": 0,
            "patch_s": 0.0,
        }
        if self.correction == "patch":
            if self._graph is None:
                self._graph = node_graph(K)  # the pattern is the mesh's: built once
            nodes = residual_patch(
                np.where(self._free, f - Ku, 0.0), self._graph, threshold=self.patch_threshold,
                layers=self.patch_layers, max_nodes=self.patch_max_nodes,
            )  # fmt: skip
            patched = patch_correct(K, f, u, Ku, self._free, nodes)
            u, after = patched.u, patched.residual_after
            extra.update(patch_nodes=patched.nodes, patch_s=time.perf_counter() - t2)
        extra["residual_after"] = after
        tol = self.guard_tolerance
        if tol is None or after <= tol:
            return MechanicsOutput(u=u, iterations=0, residual=after, extra=extra)
        rebuilt, loose = False, None
        if self._preconditioners.kind == "jacobi":
            corr = jacobi_cg(K, f, u, self._free, tol=tol, maxiter=self.guard_maxiter)
        else:
            solver, rebuilt = self.operator_for(youngs_modulus_pa, healthy)
            corr = correct(
                solver, u, pressure_pa, self.p0_pa, tol=tol, maxiter=self.guard_maxiter,
                preconditioner=self._preconditioners,
            )  # fmt: skip
            if solver.fragments.loose.any():
                loose = solver.fragments.loose
        self.n_corrections += 1
        extra.update(
            guard_setup_s=corr.setup_s,
            guard_solve_s=corr.solve_s,
            residual_after=corr.residual_after,
            guard_iterations=corr.iterations,
            corrected=True,
        )
        return MechanicsOutput(
            u=corr.u,
            iterations=corr.iterations,
            residual=corr.residual_after,
            rebuilt=rebuilt,
            loose_tets=loose,
            extra=extra,
        )
