"""The stored PGD model: modes M_i(x), parameter functions N_i(s), R_i(r), S_i(g), and its file.

u(x; s, Q, r, g) = Q * sum_i M_i(x) N_i(s) R_i(r) S_i(g) + Q * sum_j online modes. N lives on a
tensor grid of electrode positions (bilinear), R on a 1-D grid of bump radii (linear), S at the
training topologies' kernel-PCA coordinates (linear RBF interpolation). Every parameter is
clamped to its training range: the model never extrapolates, it saturates (and says so).
Online modes are rank-one terms whose parameter functions are hats centred on the state where
they were added (width one training-grid step), so they correct that state and its neighbours.

File: ``.npz`` (no pickles) with a JSON ``meta`` entry -- format name + version, grid, block,
material, parameter ranges, enrichment history -- so a model states what it was built for.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.interpolate import RBFInterpolator

from diathermy.errors import CheckpointError
from diathermy.surrogates.pgd.kpca import TopologyMap, topology_map_from
from diathermy.version import __version__

FORMAT_NAME = "diathermy-pgd"
FORMAT_VERSION = 1
_ARRAYS = ("s_x", "s_y", "radius_m", "M", "N", "R", "S", "kpca_features", "kpca_coords")
_ONLINE = ("online_M", "online_centre")


def _linear_weights(grid: np.ndarray, x: float) -> tuple[np.ndarray, np.ndarray]:
    """Indices (2,) and weights (2,) of linear interpolation on a sorted 1-D grid, clamped."""
    if grid.size == 1:
        return np.array([0, 0]), np.array([1.0, 0.0])
    x = float(np.clip(x, grid[0], grid[-1]))
    i = int(np.clip(np.searchsorted(grid, x, side="right") - 1, 0, grid.size - 2))
    t = (x - grid[i]) / (grid[i + 1] - grid[i])
    return np.array([i, i + 1]), np.array([1.0 - t, t])


def _hat(t: np.ndarray) -> np.ndarray:
    return np.maximum(0.0, 1.0 - np.abs(t))


@dataclass(frozen=True)
class PGDModel:
    """A built PGD model; see the module docstring. D = 3 n_nodes DOFs, n modes.

    Attributes:
        grid_shape: (nz, ny, nx) nodes; block_m: (Lx, Ly, Lz) m.
        material: E (Pa), nu, p0 (Pa), ersatz ratio of the snapshots.
        s_x, s_y: electrode position grids (m); radius_m: bump radius grid (m).
        topology: the kPCA map of the training level sets.
        M (n, D) m per Pa m^3; N (n, n_sx, n_sy); R (n, n_r); S (n, n_topo).
        residual_history: relative Frobenius residual of the snapshot tensor after each mode.
        online_M (k, D), online_centre (k, 3 + d): modes added online and where (s_x, s_y, r, g).
    """

    grid_shape: tuple[int, int, int]
    block_m: tuple[float, float, float]
    material: dict[str, float]
    s_x: np.ndarray
    s_y: np.ndarray
    radius_m: np.ndarray
    topology: TopologyMap
    M: np.ndarray = field(repr=False)
    N: np.ndarray = field(repr=False)
    R: np.ndarray = field(repr=False)
    S: np.ndarray = field(repr=False)
    residual_history: tuple[float, ...] = ()
    online_M: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)), repr=False)
    online_centre: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)), repr=False)
    build_info: dict[str, Any] = field(default_factory=dict)
    _S_interp: Any = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        n = self.M.shape[0]
        if self.N.shape != (n, self.s_x.size, self.s_y.size) or self.R.shape != (
            n,
            self.radius_m.size,
        ):
            raise ValueError("mode and parameter-function shapes disagree")
        if self.S.shape != (n, self.topology.coords.shape[0]):
            raise ValueError("S must have one value per mode and training topology")
        if self.online_M.size == 0:
            object.__setattr__(self, "online_M", np.zeros((0, self.M.shape[1])))
            object.__setattr__(self, "online_centre", np.zeros((0, 3 + self.g_dim)))
        interp = RBFInterpolator(self.topology.coords, self.S.T, kernel="linear", degree=0)
        object.__setattr__(self, "_S_interp", interp)

    @property
    def n_modes(self) -> int:
        return int(self.M.shape[0])

    @property
    def n_online(self) -> int:
        return int(self.online_M.shape[0])

    @property
    def g_dim(self) -> int:
        return int(self.topology.coords.shape[1])

    def clamp(self, s: tuple[float, float], r: float, g: np.ndarray) -> tuple[np.ndarray, bool]:
        """The parameter point (2 + 1 + d,) clamped to the training box, and whether it was inside."""
        c = self.topology.coords
        lo = np.concatenate([[self.s_x[0], self.s_y[0], self.radius_m[0]], c.min(axis=0)])
        hi = np.concatenate([[self.s_x[-1], self.s_y[-1], self.radius_m[-1]], c.max(axis=0)])
        x = np.concatenate([np.asarray(s, float), [float(r)], np.asarray(g, float).ravel()])
        tol = 1e-9 * np.maximum(hi - lo, 1e-30)
        inside = bool(np.all((x >= lo - tol) & (x <= hi + tol)))
        return np.clip(x, lo, hi), inside

    def coefficients(
        self, s: tuple[float, float], r: float, g: np.ndarray, n_modes: int | None = None
    ) -> np.ndarray:
        """N_i(s) R_i(r) S_i(g) (n,) for the first n_modes modes (all by default), clamped."""
        x, _ = self.clamp(s, r, g)
        n = self.n_modes if n_modes is None else min(int(n_modes), self.n_modes)
        ix, wx = _linear_weights(self.s_x, x[0])
        iy, wy = _linear_weights(self.s_y, x[1])
        ir, wr = _linear_weights(self.radius_m, x[2])
        N = np.einsum("nab,a,b->n", self.N[:n][:, ix][:, :, iy], wx, wy)
        R = self.R[:n][:, ir] @ wr
        S = self._S_interp(x[3:][None, :])[0][:n]
        return N * R * S

    def online_weights(self, s: tuple[float, float], r: float, g: np.ndarray) -> np.ndarray:
        """Hat weights (k,) of the online modes at this parameter point."""
        if self.n_online == 0:
            return np.zeros(0)
        x, _ = self.clamp(s, r, g)
        h = self.online_widths()
        t = (x[None, :] - self.online_centre) / h[None, :]
        w = _hat(t[:, 0]) * _hat(t[:, 1]) * _hat(t[:, 2])
        if self.g_dim:
            w = w * _hat(np.linalg.norm(t[:, 3:], axis=1))
        return w

    def online_widths(self) -> np.ndarray:
        """Support (3 + d,) of an online mode's hats: one training-grid step per parameter."""

        def step(a: np.ndarray) -> float:
            return float(np.min(np.diff(a))) if a.size > 1 else 1.0

        c = self.topology.coords
        d = np.linalg.norm(c[:, None, :] - c[None, :, :], axis=2)
        hg = float(np.min(d[np.triu_indices(len(c), 1)])) if len(c) > 1 else 1.0
        return np.array([step(self.s_x), step(self.s_y), step(self.radius_m)] + [hg] * self.g_dim)

    def unit_displacement(
        self,
        s: tuple[float, float],
        r: float,
        g: np.ndarray,
        n_modes: int | None = None,
        *,
        online: bool = True,
    ) -> np.ndarray:
        """U (n_nodes, 3) in m per Pa m^3 of overpressure strength at (s, r, g)."""
        c = self.coefficients(s, r, g, n_modes)
        u = c @ self.M[: c.size]
        if online and self.n_online:
            u = u + self.online_weights(s, r, g) @ self.online_M
        return u.reshape(-1, 3)

    def with_online_mode(
        self, mode: np.ndarray, s: tuple[float, float], r: float, g: np.ndarray
    ) -> PGDModel:
        """A copy with one more online mode (D,) centred at (s, r, g), clamped to the box."""
        x, _ = self.clamp(s, r, g)
        return replace(
            self,
            online_M=np.vstack([self.online_M, np.asarray(mode, float).ravel()[None, :]]),
            online_centre=np.vstack([self.online_centre, x[None, :]]),
        )

    def truncated(self, n_modes: int) -> PGDModel:
        """The model with only its first n_modes offline modes (greedy: exactly the smaller model)."""
        n = max(1, min(int(n_modes), self.n_modes))
        return replace(
            self,
            M=self.M[:n],
            N=self.N[:n],
            R=self.R[:n],
            S=self.S[:n],
            residual_history=self.residual_history[:n],
        )

    def meta(self) -> dict[str, Any]:
        """The self-description written to the file."""
        return {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "diathermy_version": __version__,
            "grid_shape": list(self.grid_shape),
            "block_m": list(self.block_m),
            "material": dict(self.material),
            "n_modes": self.n_modes,
            "n_online": self.n_online,
            "ranges": {
                "electrode_x_m": [float(self.s_x[0]), float(self.s_x[-1]), int(self.s_x.size)],
                "electrode_y_m": [float(self.s_y[0]), float(self.s_y[-1]), int(self.s_y.size)],
                "radius_m": [
                    float(self.radius_m[0]),
                    float(self.radius_m[-1]),
                    int(self.radius_m.size),
                ],
                "topologies": int(self.topology.coords.shape[0]),
            },
            "kpca": {
                "band_m": self.topology.band_m,
                "gamma": self.topology.gamma,
                "n_components": self.topology.n_components,
            },
            "residual_history": list(self.residual_history),
            "build_info": self.build_info,
        }


def save_model(model: PGDModel, path: str | Path) -> Path:
    """Write the model as a self-describing ``.npz`` (written whole, then renamed into place)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {
        "meta": np.array(json.dumps(model.meta())),
        "s_x": model.s_x,
        "s_y": model.s_y,
        "radius_m": model.radius_m,
        "M": model.M,
        "N": model.N,
        "R": model.R,
        "S": model.S,
        "kpca_features": model.topology.features,
        "kpca_coords": model.topology.coords,
        "online_M": model.online_M,
        "online_centre": model.online_centre,
    }
    tmp = path.with_name(path.name + ".part")
    with tmp.open("wb") as fh:
        np.savez_compressed(fh, **arrays)  # type: ignore[arg-type]
    tmp.replace(path)
    return path


def _read(path: Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    if not path.is_file():
        raise CheckpointError(f"model file {str(path)!r} does not exist")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise CheckpointError(f"{str(path)!r} is not a readable PGD model file ({err})") from None
    if "meta" not in arrays:
        raise CheckpointError(f"{str(path)!r} is not a diathermy PGD model (foreign file)")
    try:
        meta = json.loads(str(arrays.pop("meta")))
    except json.JSONDecodeError:
        raise CheckpointError(f"{str(path)!r} is a corrupt PGD model: unreadable meta") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        raise CheckpointError(f"{str(path)!r} is not a diathermy PGD model (foreign file)")
    if meta.get("format_version") != FORMAT_VERSION:
        raise CheckpointError(
            f"{str(path)!r} has PGD format version {meta.get('format_version')!r}; this "
            f"diathermy reads version {FORMAT_VERSION} (rebuild the model with pgd-build)"
        )
    missing = [k for k in _ARRAYS + _ONLINE if k not in arrays]
    if missing:
        raise CheckpointError(f"{str(path)!r} is a corrupt PGD model: missing {missing}")
    return meta, arrays


def load_model(
    path: str | Path,
    *,
    grid_shape: tuple[int, int, int] | None = None,
    block_m: tuple[float, float, float] | None = None,
) -> PGDModel:
    """Read and validate a model; raises ``CheckpointError`` with a one-line reason.

    With ``grid_shape``/``block_m`` given, a model built for another grid or block is rejected.
    """
    path = Path(path)
    meta, a = _read(path)
    try:
        gz, gy, gx = (int(v) for v in meta["grid_shape"])
        bx, by, bz = (float(v) for v in meta["block_m"])
        grid, block = (gz, gy, gx), (bx, by, bz)
        kp = meta["kpca"]
        topo = topology_map_from(
            a["kpca_features"], kp["band_m"], kp["gamma"], int(kp["n_components"])
        )
        if not np.allclose(topo.coords, a["kpca_coords"], rtol=1e-6, atol=1e-9):
            raise ValueError("the kernel PCA map does not reproduce its stored coordinates")
        if a["M"].shape[1] != 3 * grid[0] * grid[1] * grid[2]:
            raise ValueError(
                f"modes have {a['M'].shape[1]} DOFs, grid {grid} needs {3 * np.prod(grid)}"
            )
        model = PGDModel(
            grid_shape=grid,
            block_m=block,
            material={k: float(v) for k, v in meta["material"].items()},
            s_x=a["s_x"],
            s_y=a["s_y"],
            radius_m=a["radius_m"],
            topology=topo,
            M=a["M"],
            N=a["N"],
            R=a["R"],
            S=a["S"],
            residual_history=tuple(float(v) for v in meta.get("residual_history", [])),
            online_M=a["online_M"],
            online_centre=a["online_centre"],
            build_info=dict(meta.get("build_info", {})),
        )
    except (KeyError, TypeError, ValueError, IndexError) as err:
        raise CheckpointError(f"{str(path)!r} is a corrupt PGD model: {err}") from None
    if grid_shape is not None and tuple(grid_shape) != grid:
        raise CheckpointError(
            f"{str(path)!r} was built for grid {'x'.join(map(str, grid))}, the scene uses "
            f"{'x'.join(map(str, grid_shape))} (rebuild it with pgd-build)"
        )
    if block_m is not None and not np.allclose(block_m, block, rtol=1e-9):
        raise CheckpointError(
            f"{str(path)!r} was built for block {block} m, the scene's is {block_m}"
        )
    return model
