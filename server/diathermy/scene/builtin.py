"""The built-in scenes: the paper's two scenarios, coagulation only, and the default main job."""

from __future__ import annotations

from collections.abc import Callable

from diathermy.errors import SceneError
from diathermy.scene.models import Electrode, ElectrodePath, Scene

MOVING_PATH_M = [(0.04, 0.05), (0.07, 0.035), (0.10, 0.06), (0.13, 0.04), (0.16, 0.05)]
"""A curvilinear path on the top surface (x, y) in m, ~14 cm long: 12 s at 12.35 mm/s."""


def _fixed() -> Scene:
    return Scene(
        name="fixed-electrode",
        description="The paper's fixed-electrode scenario: a 50 W ball electrode held at the "
        "centre of the top surface for 12 s (400 steps of 0.03 s), all effects.",
        steps=400,
    )


def _moving() -> Scene:
    path = ElectrodePath(waypoints_m=MOVING_PATH_M, speed_m_per_s=12.35e-3, kind="spline")
    return Scene(
        name="moving-electrode",
        description="The paper's moving-electrode scenario: a 50 W ball electrode drawn along a "
        "curvilinear path at 12.35 mm/s for 12 s, all effects.",
        electrodes=[Electrode(position_m=MOVING_PATH_M[0], path=path)],
        steps=400,
    )


MOVING_SLOW_SPEED_M_PER_S = 2.0e-3
"""Speed of ``moving-electrode-slow``: the slowest of 2 / 4 / 12.35 mm/s measured on 33x33x65 that
cuts within 12 s (first cut at 2.8 s, 390 mm^3 and peak 5.8 MPa by 12 s; 4 mm/s boils to ~0.5 MPa
but had not cut by 7.9 s; 12.35 mm/s never boils: the 3.1 mm cells under-resolve the 1.17 mm
contact)."""


def _moving_slow() -> Scene:
    path = ElectrodePath(
        waypoints_m=MOVING_PATH_M, speed_m_per_s=MOVING_SLOW_SPEED_M_PER_S, kind="spline"
    )
    return Scene(
        name="moving-electrode-slow",
        description="The moving-electrode path at 2 mm/s, slow enough to vaporize and cut on the "
        "default 33x33x65 grid (the paper's 12.35 mm/s never boils there): 50 W, 12 s, all "
        "effects. The held-out moving scene of the surrogate benchmarks.",
        electrodes=[Electrode(position_m=MOVING_PATH_M[0], path=path)],
        steps=400,
    )


def _coagulation() -> Scene:
    return Scene(
        name="coagulation",
        description="Electric and thermal only (no vaporization, no mechanics): a 20 W "
        "electrode coagulating for 6 s, with the Arrhenius burn map.",
        electrodes=[Electrode(power_w=20.0)],
        effects=["electric", "thermal", "thermal_damage"],
        steps=200,
    )


def _default() -> Scene:
    return Scene(
        name="default",
        description="The README's main job: the fixed-electrode scene on the 33x33x65 grid, "
        "3 s (100 steps), all effects.",
        steps=100,
    )


_BUILTIN: dict[str, Callable[[], Scene]] = {
    "default": _default,
    "fixed-electrode": _fixed,
    "moving-electrode": _moving,
    "moving-electrode-slow": _moving_slow,
    "coagulation": _coagulation,
}


def builtin_scene_names() -> list[str]:
    """Names of the built-in scenes."""
    return list(_BUILTIN)


def builtin_scene(name: str) -> Scene:
    """A built-in scene by name; unknown names raise ``SceneError`` listing the known ones."""
    try:
        return _BUILTIN[name]()
    except KeyError:
        raise SceneError(
            f"unknown scene {name!r}; built-in scenes: {', '.join(_BUILTIN)}"
        ) from None
