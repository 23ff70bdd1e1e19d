"""Offline PGD: FEM snapshots on the training manifold, then greedy rank-one enrichment.

The training manifold is a tensor grid: electrode positions s (x, y) on the top surface x bump
radii r x topologies (hemispherical craters, intact included). Each point is one FEM solve of a
unit-strength overpressure bump centred on the contact point below s (``parameters``). The
snapshot tensor U (D, n_s, n_r, n_g) is then decomposed greedily: each new mode is the best
rank-one fit M (x) N (x) R (x) S of the residual, found by alternating fixed-point updates (each
factor in turn is the least-squares optimum with the others fixed), until the residual's
relative Frobenius norm falls below ``tol`` or ``n_modes`` modes exist.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from diathermy.errors import SceneError
from diathermy.fem.geometry import ElementGeometry, structured_geometry
from diathermy.mesh import Grid, TetMesh, build_tet_mesh
from diathermy.physics.materials import Tissue, ersatz_youngs_modulus
from diathermy.physics.mechanics import MechanicsSolver, mechanics_assembler
from diathermy.physics.topology import contact_height, evaluate_topology
from diathermy.surrogates.pgd.kpca import fit_topology_map
from diathermy.surrogates.pgd.model import PGDModel
from diathermy.surrogates.pgd.parameters import bump_pressure, healthy_node_weights


@dataclass(frozen=True)
class TrainingManifold:
    """The sampled parameter grid and the enrichment knobs.

    Attributes:
        electrode_x_m, electrode_y_m: electrode positions (tensor grid) on the top surface, m.
        radius_m: bump radii r, m (RMS radius sqrt(3/2) r).
        craters: topologies as hemispherical craters (x, y, R) in m centred on the top surface;
            R = 0 is the intact block. At least two distinct ones (kernel PCA needs a spread).
        n_modes: most modes to build (1..50); tol: stop when the relative residual is below it.
        kpca_components: topology coordinates (at most n_topologies - 1).
        fem_rtol: CG tolerance of the snapshot solves.
        max_fixed_point, fixed_point_tol: the alternating updates of one mode.
    """

    electrode_x_m: tuple[float, ...]
    electrode_y_m: tuple[float, ...]
    radius_m: tuple[float, ...]
    craters: tuple[tuple[float, float, float], ...]
    n_modes: int = 30
    tol: float = 1e-4
    kpca_components: int = 2
    fem_rtol: float = 1e-8
    max_fixed_point: int = 50
    fixed_point_tol: float = 1e-6

    def __post_init__(self) -> None:
        for name in ("electrode_x_m", "electrode_y_m", "radius_m"):
            v = np.asarray(getattr(self, name), dtype=float)
            if v.ndim != 1 or v.size < 1 or not np.all(np.isfinite(v)) or np.any(np.diff(v) <= 0):
                raise SceneError(f"{name}: a non-empty strictly increasing list of numbers (m)")
            object.__setattr__(self, name, tuple(float(x) for x in v))
        if min(self.radius_m) <= 0:
            raise SceneError("radius_m: bump radii must be positive")
        craters = tuple(tuple(float(x) for x in c) for c in self.craters)
        if len(craters) < 2 or any(len(c) != 3 or c[2] < 0 for c in craters):
            raise SceneError("craters: at least two (x, y, R >= 0) entries in m")
        object.__setattr__(self, "craters", craters)
        if not 1 <= int(self.n_modes) <= 50:
            raise SceneError(f"n_modes must be in 1..50, got {self.n_modes}")
        if not self.tol > 0 or not self.fem_rtol > 0:
            raise SceneError("tol and fem_rtol must be positive")

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrainingManifold:
        """From a config mapping (the ``pgd-build`` file's ``manifold`` section)."""
        known = set(cls.__dataclass_fields__)
        unknown = set(data) - known
        if unknown:
            raise SceneError(f"unknown training-manifold keys: {sorted(unknown)}")
        try:
            return cls(**data)
        except TypeError as err:
            raise SceneError(f"training manifold: {err}") from None


def crater_level_set(grid: Grid, centre_xy: tuple[float, float], radius_m: float) -> np.ndarray:
    """phi (n_nodes,) in m of the block minus a ball of radius R centred on the top at (x, y).

    min(z_top - z, |x - c| - R): positive in tissue, a signed distance away from the rim; R = 0
    gives the intact block's phi = z_top - z.
    """
    pts = grid.points()
    z_top = grid.origin_m[2] + grid.size_m[2]
    c = np.array([centre_xy[0], centre_xy[1], z_top])
    return np.minimum(z_top - pts[:, 2], np.linalg.norm(pts - c, axis=1) - radius_m)


def snapshot_tensor(
    manifold: TrainingManifold,
    grid: Grid,
    tissue: Tissue,
    progress: Callable[[str], None] | None = None,
) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """U (D, n_sx * n_sy, n_r, n_topo) in m per Pa m^3, level sets (n_topo, n_nodes), timings."""
    mesh: TetMesh = build_tet_mesh(grid)
    geom: ElementGeometry = structured_geometry(mesh.points, mesh.tets, mesh.shape_id)
    sx, sy, rs = manifold.electrode_x_m, manifold.electrode_y_m, manifold.radius_m
    n_s = len(sx) * len(sy)
    U = np.zeros((3 * mesh.n_nodes, n_s, len(rs), len(manifold.craters)))
    phis = np.zeros((len(manifold.craters), mesh.n_nodes))
    assembler = mechanics_assembler(mesh)
    p0 = tissue.p_atm_pa
    t_setup = t_solve = 0.0
    for ig, (cx, cy, cr) in enumerate(manifold.craters):
        t0 = time.perf_counter()
        phi = crater_level_set(grid, (cx, cy), cr)
        phis[ig] = phi
        topo = evaluate_topology(phi, mesh, geom.volumes)
        removed = topo.removed | topo.loose
        E = ersatz_youngs_modulus(~removed, tissue.youngs_modulus_pa, tissue.ersatz_stiffness_ratio)
        solver = MechanicsSolver(
            mesh,
            E,
            tissue.poisson_ratio,
            healthy=~removed,
            ersatz_ratio=tissue.ersatz_stiffness_ratio,
            rtol=manifold.fem_rtol,
            assembler=assembler,
        )
        w = healthy_node_weights(mesh.tets, geom.volumes, solver.healthy, mesh.n_nodes)
        phi_grid = phi.reshape(grid.shape)
        t_setup += time.perf_counter() - t0
        t0 = time.perf_counter()
        for i, x in enumerate(sx):
            for j, y in enumerate(sy):
                centre = np.array([x, y, float(contact_height(phi_grid, grid, x, y))])
                for ir, r in enumerate(rs):
                    dp = bump_pressure(mesh.points, centre, r, w)
                    U[:, i * len(sy) + j, ir, ig] = solver.solve(p0 + dp, p0).u.ravel()
        t_solve += time.perf_counter() - t0
        if progress is not None:
            progress(f"topology {ig + 1}/{len(manifold.craters)}: {n_s * len(rs)} FEM solves")
    return U, phis, {"fem_setup_s": t_setup, "fem_solve_s": t_solve}


def _contract(T: np.ndarray, vecs: Sequence[np.ndarray], skip: int) -> np.ndarray:
    """T contracted with vecs[k] along every axis k except ``skip``: a vector along ``skip``."""
    out = T
    for k in reversed(range(T.ndim)):  # last axis first, so lower axis numbers stay valid
        if k != skip:
            out = np.tensordot(out, vecs[k], axes=([k], [0]))
    return out


def _outer(vecs: Sequence[np.ndarray]) -> np.ndarray:
    out = vecs[0]
    for v in vecs[1:]:
        out = np.multiply.outer(out, v)
    return out


@dataclass(frozen=True)
class Enrichment:
    """Greedy decomposition: factors[k] (n, d_k), relative residual and fixed-point sweeps per mode."""

    factors: tuple[np.ndarray, ...]
    residual_history: tuple[float, ...]
    sweeps: tuple[int, ...]


def rank_one_enrichment(
    U: np.ndarray,
    n_modes: int,
    *,
    tol: float = 1e-4,
    max_fixed_point: int = 50,
    fixed_point_tol: float = 1e-6,
) -> Enrichment:
    """Greedy PGD of a d-way tensor U: sum_i F0_i (x) F1_i (x) ... with alternating updates.

    Each mode starts from the residual's largest parameter slice and sweeps the factors (each the
    least-squares optimum given the others) until the rank-one term changes by less than
    ``fixed_point_tol`` (relative); modes stop at ``n_modes`` or when ||res|| / ||U|| < tol.
    Parameter factors (k >= 1) have unit norm; the first factor carries the amplitude.
    """
    U = np.asarray(U, dtype=float)
    n_param = int(np.prod(U.shape[1:]))
    basis = None
    if U.shape[0] > n_param:
        # Every spatial factor is a contraction of the residual, so it lies in the column span of
        # the unfolding U_(0) (D, n_param). With U_(0) = Q C (Q orthonormal) the greedy PGD of C is
        # the same decomposition at n_param / D of the cost; M = Q m afterwards.
        basis, C = np.linalg.qr(U.reshape(U.shape[0], n_param))
        res = C.reshape(n_param, *U.shape[1:])
    else:
        res = U.copy()
    norm_u = float(np.linalg.norm(res))
    factors: list[list[np.ndarray]] = [[] for _ in range(U.ndim)]
    history: list[float] = []
    sweeps: list[int] = []
    if norm_u == 0.0:
        raise ValueError("the snapshot tensor is zero: nothing to decompose")
    for _ in range(int(n_modes)):
        if history and history[-1] < tol:
            break
        slice_norms = np.linalg.norm(res.reshape(res.shape[0], -1), axis=0)
        start = np.unravel_index(int(np.argmax(slice_norms)), res.shape[1:])
        vecs = [np.zeros(res.shape[0])] + [
            np.eye(d)[i] for d, i in zip(res.shape[1:], start, strict=True)
        ]
        old = None
        n_sweeps = 0
        for _ in range(max_fixed_point):
            n_sweeps += 1
            for j in range(U.ndim):
                denom = np.prod([vecs[m] @ vecs[m] for m in range(U.ndim) if m != j])
                vecs[j] = _contract(res, vecs, j) / denom
                if j > 0:  # keep the amplitude in the first factor
                    nrm = np.linalg.norm(vecs[j])
                    if nrm == 0.0:
                        break
                    vecs[j] = vecs[j] / nrm
            nrm2 = np.prod([v @ v for v in vecs])
            if old is not None:
                cross = np.prod([a @ b for a, b in zip(vecs, old, strict=True)])
                change = max(nrm2 + np.prod([v @ v for v in old]) - 2 * cross, 0.0)
                if change <= fixed_point_tol**2 * nrm2:
                    break
            old = [v.copy() for v in vecs]
        res -= _outer(vecs)
        for j in range(U.ndim):
            factors[j].append(vecs[j])
        history.append(float(np.linalg.norm(res)) / norm_u)
        sweeps.append(n_sweeps)
    out = [np.array(f) for f in factors]
    if basis is not None:
        out[0] = out[0] @ basis.T
    return Enrichment(tuple(out), tuple(history), tuple(sweeps))


def build_model(
    manifold: TrainingManifold,
    grid_shape: tuple[int, int, int],
    block_m: tuple[float, float, float],
    tissue: Tissue,
    progress: Callable[[str], None] | None = None,
) -> PGDModel:
    """FEM snapshots on the manifold, then the greedy PGD; the model of ``grid_shape``/``block_m``."""
    grid = Grid(grid_shape, size_m=block_m)
    lo, hi = np.asarray(grid.origin_m), np.asarray(grid.origin_m) + np.asarray(grid.size_m)
    for name, vals, axis in (
        ("electrode_x_m", manifold.electrode_x_m, 0),
        ("electrode_y_m", manifold.electrode_y_m, 1),
    ):
        if min(vals) < lo[axis] or max(vals) > hi[axis]:
            raise SceneError(
                f"{name}: positions must lie on the top surface [{lo[axis]}, {hi[axis]}] m"
            )
    t0 = time.perf_counter()
    U, phis, timings = snapshot_tensor(manifold, grid, tissue, progress)
    t1 = time.perf_counter()
    topo = fit_topology_map(phis, 2.0 * max(grid.spacing_m), manifold.kpca_components)
    enr = rank_one_enrichment(
        U,
        manifold.n_modes,
        tol=manifold.tol,
        max_fixed_point=manifold.max_fixed_point,
        fixed_point_tol=manifold.fixed_point_tol,
    )
    t2 = time.perf_counter()
    n = len(enr.residual_history)
    M, Ns, R, S = enr.factors
    if progress is not None:
        progress(f"{n} modes, relative residual {enr.residual_history[-1]:.2e}")
    return PGDModel(
        grid_shape=tuple(int(v) for v in grid_shape),  # type: ignore[arg-type]
        block_m=tuple(float(v) for v in block_m),  # type: ignore[arg-type]
        material={
            "youngs_modulus_pa": tissue.youngs_modulus_pa,
            "poisson_ratio": tissue.poisson_ratio,
            "p_atm_pa": tissue.p_atm_pa,
            "ersatz_stiffness_ratio": tissue.ersatz_stiffness_ratio,
        },
        s_x=np.asarray(manifold.electrode_x_m),
        s_y=np.asarray(manifold.electrode_y_m),
        radius_m=np.asarray(manifold.radius_m),
        topology=topo,
        M=M,
        N=Ns.reshape(n, len(manifold.electrode_x_m), len(manifold.electrode_y_m)),
        R=R,
        S=S,
        residual_history=enr.residual_history,
        build_info={
            "snapshots": int(np.prod(U.shape[1:])),
            "craters": [list(c) for c in manifold.craters],
            "fixed_point_sweeps": list(enr.sweeps),
            "snapshot_s": t1 - t0,
            "enrichment_s": t2 - t1,
            **timings,
        },
    )
