"""The topology coordinate g: kernel PCA of level-set snapshots, with out-of-sample projection.

A level set is reduced to its band around the cut, phi clipped to [-b, b] / b with b = two grid
spacings: far from the surface every snapshot agrees, so only the cut's shape enters the kernel.
The RBF kernel's gamma is 1 / median squared distance of the training features. A topology far
from every training snapshot has kernel values near 0 and projects near the training mean --
kernel PCA cannot say *how* far off the manifold it is; ``distance`` can.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sklearn.decomposition import KernelPCA


def level_set_features(level_set_m: np.ndarray, band_m: float) -> np.ndarray:
    """clip(phi / band, -1, 1) flattened (n_nodes,), the cut's band; phi in m."""
    return np.clip(np.asarray(level_set_m, dtype=float).ravel() / band_m, -1.0, 1.0)


@dataclass(frozen=True)
class TopologyMap:
    """Kernel PCA of training features (n_topo, n_nodes); ``coords`` (n_topo, n_components)."""

    features: np.ndarray = field(repr=False)
    band_m: float
    gamma: float
    n_components: int
    coords: np.ndarray = field(repr=False)
    kpca: KernelPCA = field(repr=False, compare=False)

    def transform(self, level_set_m: np.ndarray) -> np.ndarray:
        """Out-of-sample coordinates g (n_components,) of one level set (n_nodes,) in m."""
        x = level_set_features(level_set_m, self.band_m)[None, :]
        return self.kpca.transform(x)[0]

    def distance(self, level_set_m: np.ndarray) -> float:
        """RMS feature distance (in [0, 2]) from a level set to its nearest training snapshot."""
        x = level_set_features(level_set_m, self.band_m)
        return float(np.sqrt(np.min(np.mean((self.features - x) ** 2, axis=1))))


def _kpca(features: np.ndarray, gamma: float, n_components: int) -> KernelPCA:
    kp = KernelPCA(n_components=n_components, kernel="rbf", gamma=gamma, eigen_solver="dense")
    kp.fit(features)
    return kp


def fit_topology_map(level_sets_m: np.ndarray, band_m: float, n_components: int = 2) -> TopologyMap:
    """Fit the map on level-set snapshots (n_topo, n_nodes) in m; needs >= 2 distinct snapshots."""
    feats = np.stack([level_set_features(p, band_m) for p in level_sets_m])
    n = feats.shape[0]
    if n < 2:
        raise ValueError("kernel PCA of the topology needs at least 2 level-set snapshots")
    d2 = np.sum((feats[:, None, :] - feats[None, :, :]) ** 2, axis=2)[np.triu_indices(n, 1)]
    med = float(np.median(d2))
    if med <= 0.0:
        raise ValueError("the level-set snapshots are identical: no topology to reduce")
    k = max(1, min(int(n_components), n - 1))
    return topology_map_from(feats, band_m, 1.0 / med, k)


def topology_map_from(
    features: np.ndarray, band_m: float, gamma: float, n_components: int
) -> TopologyMap:
    """Rebuild the map from stored features (deterministic: dense eigensolver)."""
    features = np.asarray(features, dtype=float)
    kp = _kpca(features, gamma, n_components)
    coords = kp.transform(features)
    return TopologyMap(features, float(band_m), float(gamma), int(n_components), coords, kp)
