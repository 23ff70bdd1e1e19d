"""The built-in scenes: the paper's two scenarios, coagulation only, and the default main job."""

from __future__ import annotations

from collections.abc import Callable

from diathermy.errors import SceneError
from diathermy.scene.models import Electrode, ElectrodePath, Scene
from diathermy.scene.resolution import Resolution

MOVING_PATH_M = [(0.04, 0.05), (0.07, 0.035), (0.10, 0.06), (0.13, 0.04), (0.16, 0.05)]
"""A curvilinear path on the top surface (x, y) in m, ~14 cm long: 12 s at 12.35 mm/s."""


FIXED_RESOLUTION = Resolution(deep_m=90e-3, surface_m=0.1e-3)
"""The fixed electrode's grid: 0.4 mm cells over the contact + 2 mm, 12 mm deep, shrinking to
0.1 mm at the top surface, and a deep tier below it to 90 mm (cells 0.4 mm wide, at most 0.8 mm
tall), growing by 1.25 to 6.25 mm outside (140x49x65 = 446 k nodes). Its 50 W crater leaves the
12 mm at 1.71 s and is 79.5 mm deep at 12 s: without the tier (169 k nodes) the crater was
0.83 / 0.64 of the tiered grid's at 6 / 12 s, in cells growing to 6.25 mm; the tier costs 2.6x
the nodes, 3.5x the median step and 2.3x the memory (7133 against 3081 MiB;
benchmarks/results/fixed_depth.md). The 0.1 mm top cells resolve the layer that boils first: the
first cut (current-density drive) at 0.0511 s against 0.0520 s on 0.2 / 0.05 mm, where 0.4 mm
cells up to the surface give 0.0633 s (+22 %; benchmarks/results/convergence.md)."""

COAGULATION_RESOLUTION = Resolution()
"""The coagulation scene's grid: the fixed electrode's without the deep tier (no crater; the
lesion is ~0.8 mm deep)."""

MOVING_RESOLUTION = Resolution(fine_m=1e-3, depth_m=3e-3)
"""The moving electrodes' grid: 1 mm cells over the path's bounding box + 2 mm, 3 mm deep. The
whole path is the working region, so finer cells cost nodes fast (0.5 mm: 1.3 M nodes)."""

MAIN_JOB_RESOLUTION = Resolution(fine_m=1e-3, depth_m=16e-3)
"""The default main job's grid: 1 mm over the contact + 2 mm, 16 mm deep (35x32x48 nodes), so that
its 3 s crater (13.8 mm deep) and the vapor below it stay in the fine cells. 3 mm deep (24x32x48)
took 0.64x the time (2026-12-06, 100 steps, 36.5 against 56.9 s) but the crater left the fine
cells at 1.14 s and ended 10.7 mm deep and 80.1 mm^3 against 13.8 mm and 85.1 mm^3."""


def _fixed() -> Scene:
    return Scene(
        name="fixed-electrode",
        description="The paper's fixed-electrode scenario: a 50 W ball electrode held at the "
        "centre of the top surface for 12 s (400 steps of 0.03 s), all effects, on a graded "
        "grid (0.4 mm under the electrode, 12 mm deep, 0.1 mm at the surface, and 0.4 mm wide "
        "cells at most 0.8 mm tall to 90 mm, where the crater drills).",
        resolution=FIXED_RESOLUTION,
        steps=400,
    )


def _moving() -> Scene:
    path = ElectrodePath(waypoints_m=MOVING_PATH_M, speed_m_per_s=12.35e-3, kind="spline")
    return Scene(
        name="moving-electrode",
        description="The paper's moving-electrode scenario: a 50 W ball electrode drawn along a "
        "curvilinear path at 12.35 mm/s for 12 s, all effects, on a graded grid (1 mm along "
        "the path).",
        electrodes=[Electrode(position_m=MOVING_PATH_M[0], path=path)],
        resolution=MOVING_RESOLUTION,
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
        description="The moving-electrode path at 2 mm/s, slow enough to vaporize and cut even on "
        "the uniform 33x33x65 grid (the paper's 12.35 mm/s never boils there): 50 W, 12 s, all "
        "effects, on a graded grid (1 mm along the path); the surrogate benchmarks run it on "
        "its uniform grid.",
        electrodes=[Electrode(position_m=MOVING_PATH_M[0], path=path)],
        resolution=MOVING_RESOLUTION,
        steps=400,
    )


COAGULATION_POWER_W = 0.5
"""The coagulation scene's power, W. The scene leaves vaporization out, so it holds only below
boiling: 0.5 W keeps its hottest node at 357 K after 6 s on its 0.4 mm grid (0.6 W: 366 K; the
20 W it had until 2026-12-07 passed boiling at 0.08 s and reached 2200 K). The step reports'
``left_out_effects`` say when a scene passes that line."""


def _coagulation() -> Scene:
    return Scene(
        name="coagulation",
        description="Electric and thermal only (no vaporization, no mechanics): a 0.5 W "
        "electrode coagulating for 6 s, with the Arrhenius burn map (a lesion ~0.8 mm deep). "
        "Without vaporization the scene holds only below boiling: 0.5 W keeps the hottest node "
        "at 357 K, where 20 W passed boiling in 0.08 s and reached 2200 K.",
        electrodes=[Electrode(power_w=COAGULATION_POWER_W)],
        resolution=COAGULATION_RESOLUTION,
        effects=["electric", "thermal", "thermal_damage"],
        steps=200,
    )


def _default() -> Scene:
    return Scene(
        name="default",
        description="The README's main job: the fixed-electrode scene for 3 s (100 steps), all "
        "effects, on a graded grid at 1 mm under the electrode (a few minutes on 2 cores).",
        resolution=MAIN_JOB_RESOLUTION,
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
