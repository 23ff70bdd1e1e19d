"""Where an active electrode touches the tissue: the contact disk on the healthy surface below
it, and several electrodes combined into one generator output."""

from __future__ import annotations

import numpy as np

from diathermy.engine.discretization import Discretization
from diathermy.engine.electrodes import ElectrodePose
from diathermy.engine.state import ContactKey, SimulationState
from diathermy.errors import SceneError
from diathermy.physics.contact_load import (
    N_ANGULAR,
    N_RADIAL,
    ContactWeights,
    contact_weights,
    disk_quadrature,
)
from diathermy.physics.driven_potential import ElectrodeDrive
from diathermy.physics.topology import REMOVED_FRACTION, contact_height


class ContactCache:
    """The last contact disk built (one entry: a moving electrode never comes back exactly)."""

    def __init__(self) -> None:
        self.entries: dict[ContactKey, ContactWeights] = {}

    def get(self, disc: Discretization, key: ContactKey) -> ContactWeights | None:
        """The disk of ``key``; None when it touches no node of the top surface."""
        if key not in self.entries:
            try:
                self.entries = {key: weights_of(disc, key)}
            except SceneError:
                return None
        return self.entries[key]

    def key_of(self, contact: ContactWeights) -> ContactKey | None:
        """The key of a cached disk (by identity), None when it is not cached."""
        return next((k for k, c in self.entries.items() if c is contact), None)

    def put(self, key: ContactKey, contact: ContactWeights) -> None:
        """Cache ``contact`` as the only entry (a restored run's disk)."""
        self.entries = {key: contact}


def weights_of(disc: Discretization, key: ContactKey) -> ContactWeights:
    """The nodal weights of a contact key: a flat disk (x, y, z, r), or one draped over the
    heights that follow."""
    x, y, z, r = (float(v) for v in key[:4])
    heights = np.asarray(key[4:], dtype=float) if len(key) > 4 else None
    return contact_weights(disc.mesh, (x, y, z), r, heights_m=heights)


def drives_current(pose: ElectrodePose) -> bool:
    """Whether an electrode is on and set to a positive power or current density."""
    on = pose.power_w > 0 if pose.drive == "power" else pose.current_density_a_per_m2 > 0
    return pose.active and on


def contact_level_set(disc: Discretization, state: SimulationState) -> np.ndarray:
    """phi (nz, ny, nx) in m as the electrode sees it: a loose fragment has fallen away.

    The level set still counts a fragment cut loose from the bottom as tissue (phi > 0), but
    its tets are removed; nodes with no healthy tet around them get phi < 0 here, so the
    contact drops to the healthy surface below instead of riding the fragment.
    """
    phi = state["level_set"]
    topology = state.memory.topology
    if topology is not None and topology.loose.any():
        tets = disc.mesh.tets[~state["removed"]]
        held = np.bincount(tets.ravel(), minlength=disc.n_nodes) > 0
        phi = np.where(held, phi, np.minimum(phi, -np.abs(phi) - 1e-12))
    return disc.to_grid(phi)


def draped_heights(
    disc: Discretization,
    phi_grid: np.ndarray,
    removed: np.ndarray,
    x: float,
    y: float,
    r: float,
) -> np.ndarray:
    """Height (m) of the healthy surface under each quadrature point of the contact disk at
    (x, y) of radius r; NaN where the point is off the block, its column is cut through to the
    bottom, or no healthy tet holds it.

    Each point goes on its healthy node layer as ``contact_key`` puts the centre; a point that
    still lands in a removed tet (a cell mostly healthy whose corner tet is cut) goes just under
    the layer, into the cell below, so that its current enters tissue (``removed``: per tet).
    """
    g = disc.grid
    pts, _ = disk_quadrature(np.array([x, y, 0.0]), r, N_RADIAL, N_ANGULAR)
    (x0, y0, z0), (lx, ly, _) = g.origin_m, g.size_m
    on = (pts[:, 0] >= x0) & (pts[:, 0] <= x0 + lx) & (pts[:, 1] >= y0) & (pts[:, 1] <= y0 + ly)
    z = np.full(pts.shape[0], np.nan)
    if not on.any():
        return z
    h = np.asarray(contact_height(phi_grid, g, pts[on, 0], pts[on, 1]), dtype=float)
    zs = g.axes()[2]
    kk = np.clip(np.searchsorted(zs, h, side="right") - 1, 0, zs.size - 2)
    dz = zs[kk + 1] - zs[kk]
    kk = np.where(zs[kk + 1] - h <= 1e-9 * dz, np.minimum(kk + 1, zs.size - 1), kk)
    layer = zs[kk]
    h = np.where(h - layer < REMOVED_FRACTION * dz, layer, h)

    def in_removed(heights: np.ndarray) -> np.ndarray:
        xyz = np.column_stack([pts[on, 0], pts[on, 1], np.maximum(heights, z0)])
        return np.asarray(removed[disc.mesh.locate(xyz)[0]], dtype=bool)

    bad = in_removed(h)
    if bad.any():  # just under its layer, else dropped
        h = np.where(bad, layer - 1e-6 * dz, h)
        bad = in_removed(h)
    h = np.where(bad | (h <= z0 + 1e-9 * dz), np.nan, h)
    z[on] = h
    return z


def contact_key(
    disc: Discretization, state: SimulationState, pose: ElectrodePose, *, top_z: float, cut: bool
) -> ContactKey | None:
    """The contact disk (x, y, z, r) of an electrode on the healthy surface below it; a draped
    contact (``pose.contact``) adds the height of each of its quadrature points
    (``draped_heights``), so that the disk follows the crater's surface under it instead of
    cutting through its walls at the centre's height.

    None when the cut under its centre reaches the bottom (the return electrode): no tissue is
    left between the electrodes. ``cut``: the scene dissects and some tet is removed.
    """
    x, y = pose.position_m
    z = top_z
    if cut:
        g = disc.grid
        # a centre just off an edge still touches with part of its disk: use the nearest column
        (x0, y0, z0), (lx, ly, _) = g.origin_m, g.size_m
        xc, yc = min(max(x, x0), x0 + lx), min(max(y, y0), y0 + ly)
        phi = contact_level_set(disc, state)
        z = float(contact_height(phi, g, xc, yc))
        # A front in the lower half of a cell layer leaves that layer's tets removed (half or
        # more cut): the disk goes down to the node layer under it, the top of the healthy
        # tets. Left in between, it loaded tets of sigma ~ 0 and the set power went into the
        # crater's vapor (R rose 100x and T passed 1100 K at dt 0.3 s).
        if g.is_uniform:
            dz = g.spacing_m[2]
            k = np.floor((z - z0) / dz + 1e-9)
            z_layer = z0 + k * dz
        else:  # the node layer at or below z and the cell above it
            zs = g.axes()[2]
            kk = int(np.clip(np.searchsorted(zs, z, side="right") - 1, 0, zs.size - 2))
            dz = float(zs[kk + 1] - zs[kk])
            if zs[kk + 1] - z <= 1e-9 * dz:
                kk = min(kk + 1, zs.size - 1)
            z_layer = float(zs[kk])
        if z - z_layer < REMOVED_FRACTION * dz:
            z = z_layer
        if z <= z0 + 1e-9 * dz:
            return None
        if pose.contact == "draped":
            heights = draped_heights(disc, phi, state["removed"], x, y, pose.radius_m)
            return (x, y, z, pose.radius_m, *(float(h) for h in heights))
    return (x, y, z, pose.radius_m)


def combined(
    contacts: list[tuple[ElectrodePose, ContactWeights]],
) -> tuple[ContactWeights, ElectrodeDrive]:
    """Several active electrodes act as one generator output of equal current density (the
    lowest voltage limit among them holds for the output)."""
    limits = [p.max_voltage_v for p, _ in contacts if p.max_voltage_v is not None]
    v_max = min(limits) if limits else None  # one output: the lowest limit holds
    if len(contacts) == 1:
        pose, c = contacts[0]
        mode = pose.drive
        return c, ElectrodeDrive(mode, pose.current_density_a_per_m2, pose.power_w, v_max)  # type: ignore[arg-type]
    weights = sum(c.weights for _, c in contacts)
    area = sum(c.area_m2 for _, c in contacts)
    if all(p.drive == "power" for p, _ in contacts):
        total = sum(p.power_w for p, _ in contacts)
        drive = ElectrodeDrive("power", power_w=total, max_voltage_v=v_max)
    else:
        j = sum(p.current_density_a_per_m2 * c.area_m2 for p, c in contacts) / area
        drive = ElectrodeDrive("current_density", current_density_a_per_m2=j, max_voltage_v=v_max)
    return ContactWeights(weights=np.asarray(weights), area_m2=float(area)), drive
