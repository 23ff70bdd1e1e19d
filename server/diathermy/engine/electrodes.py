"""Where each electrode is and how it is driven at a given time (pure functions of the scene)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diathermy.errors import SceneError
from diathermy.scene.models import Electrode, ElectrodePath, Scene


@dataclass(frozen=True)
class ElectrodeOverride:
    """Run-time changes to an electrode (from a front end), on top of the scene's values."""

    position_m: tuple[float, float] | None = None
    power_w: float | None = None
    current_density_a_per_m2: float | None = None
    active: bool | None = None
    max_voltage_v: float | None = None
    """The generator's voltage limit in V; 0 lifts the scene's limit (None: the scene's)."""


def _catmull_rom(points: np.ndarray, per_segment: int = 32) -> np.ndarray:
    """A centripetal-free (uniform) Catmull-Rom spline through ``points`` (n, 2), densified."""
    p = np.vstack([2 * points[0] - points[1], points, 2 * points[-1] - points[-2]])
    t = np.linspace(0.0, 1.0, per_segment, endpoint=False)[:, None]
    out = []
    for i in range(1, len(p) - 2):
        p0, p1, p2, p3 = p[i - 1], p[i], p[i + 1], p[i + 2]
        out.append(
            0.5
            * (
                2 * p1
                + (-p0 + p2) * t
                + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t**2
                + (-p0 + 3 * p1 - 3 * p2 + p3) * t**3
            )
        )
    out.append(points[-1:])
    return np.vstack(out)


def path_polyline(path: ElectrodePath) -> np.ndarray:
    """The path as a dense polyline (n, 2) in m."""
    pts = np.asarray(path.waypoints_m, dtype=float)
    return _catmull_rom(pts) if path.kind == "spline" else pts


def path_position(path: ElectrodePath, t_s: float) -> tuple[float, float]:
    """(x, y) in m reached at time t: arclength speed * (t - start), clamped to the path's ends."""
    line = path_polyline(path)
    seg = np.linalg.norm(np.diff(line, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    s = float(np.clip(path.speed_m_per_s * (t_s - path.start_s), 0.0, cum[-1]))
    x = np.interp(s, cum, line[:, 0])
    y = np.interp(s, cum, line[:, 1])
    return float(x), float(y)


@dataclass(frozen=True)
class ElectrodePose:
    """An electrode's state during one step."""

    name: str
    position_m: tuple[float, float]
    radius_m: float
    drive: str
    power_w: float
    current_density_a_per_m2: float
    active: bool
    contact: str = "flat"
    max_voltage_v: float | None = None


def electrode_pose(
    el: Electrode, t_s: float, override: ElectrodeOverride | None = None
) -> ElectrodePose:
    """The pose and drive of ``el`` at time ``t_s`` (midpoint of the step), overrides applied."""
    o = override or ElectrodeOverride()
    if o.position_m is not None:
        pos = o.position_m
    elif el.path is not None:
        pos = path_position(el.path, t_s)
    else:
        pos = el.position_m
    on = el.active if o.active is None else o.active
    if on and el.schedule_s is not None:
        on = any(t_on <= t_s < t_off for t_on, t_off in el.schedule_s)
    return ElectrodePose(
        name=el.name,
        position_m=(float(pos[0]), float(pos[1])),
        radius_m=el.radius_m,
        contact=el.contact,
        drive="power"
        if o.power_w is not None
        else ("current_density" if o.current_density_a_per_m2 is not None else el.drive),
        power_w=el.power_w if o.power_w is None else o.power_w,
        current_density_a_per_m2=(
            el.current_density_a_per_m2
            if o.current_density_a_per_m2 is None
            else o.current_density_a_per_m2
        ),
        active=bool(on),
        max_voltage_v=el.max_voltage_v
        if o.max_voltage_v is None
        else (o.max_voltage_v if o.max_voltage_v > 0 else None),
    )


def override_electrode(
    scene: Scene,
    name: str,
    old: ElectrodeOverride,
    *,
    position_m: tuple[float, float] | None = None,
    power_w: float | None = None,
    current_density_a_per_m2: float | None = None,
    active: bool | None = None,
    max_voltage_v: float | None = None,
) -> ElectrodeOverride:
    """``old`` with the given changes (None keeps a value; a new drive replaces the other;
    ``max_voltage_v`` 0 lifts the generator's voltage limit).

    Raises ``SceneError`` naming the field for an unknown electrode, a position off the top
    surface or a negative or non-finite drive.
    """
    names = [e.name for e in scene.electrodes]
    if name not in names:
        raise SceneError(f"unknown electrode {name!r}; electrodes: {', '.join(names) or 'none'}")
    lx, ly, _ = scene.block_m
    if position_m is not None:
        x, y = (float(v) for v in position_m)
        if not (np.isfinite(x) and np.isfinite(y) and 0.0 <= x <= lx and 0.0 <= y <= ly):
            raise SceneError(
                f"position_m: ({x}, {y}) lies off the top surface [0, {lx}] x [0, {ly}] m"
            )
        position_m = (x, y)
    for field_name, value in (
        ("power_w", power_w),
        ("current_density_a_per_m2", current_density_a_per_m2),
        ("max_voltage_v", max_voltage_v),
    ):
        if value is not None and not (np.isfinite(value) and value >= 0):
            raise SceneError(f"{field_name}: must be a finite number >= 0, got {value}")
    return ElectrodeOverride(
        position_m=position_m if position_m is not None else old.position_m,
        power_w=power_w
        if power_w is not None
        else (None if current_density_a_per_m2 is not None else old.power_w),
        current_density_a_per_m2=(
            current_density_a_per_m2
            if current_density_a_per_m2 is not None
            else (None if power_w is not None else old.current_density_a_per_m2)
        ),
        active=active if active is not None else old.active,
        max_voltage_v=max_voltage_v if max_voltage_v is not None else old.max_voltage_v,
    )
