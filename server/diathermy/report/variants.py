"""Variants of how a scene can be run, and what running one measures.

A variant changes only the knobs that trade accuracy for time (mechanics backend and tolerance,
grid, surrogate model, guard); everything else comes from the scene.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from typing import Literal

from diathermy.scene import Scene, scene_from_dict


@dataclass(frozen=True)
class Variant:
    """One way to run a scene. ``model`` is a surrogate file for the cnn/pgd backends."""

    name: str
    backend: Literal["fem", "cnn", "pgd"] = "fem"
    rtol: float = 1e-6
    grid: tuple[int, int, int] | None = None  # None: the scene's grid
    model: str | None = None
    guard_tolerance: float | None = None
    coupling: Literal["staggered", "monolithic"] = "staggered"
    correction: Literal["none", "patch"] = "none"  # cnn and fem-incremental: u as is, or patched
    incremental: bool = False  # fem: the previous-displacement predictor (issue #25)
    full_every: int = 10  # ... with a full solve at least every this many solves
    interval_tolerance: float = 3e-4  # ... that solve's energy-error estimate (0: FEM rtol)
    guard: Literal["auto", "residual", "energy"] = "auto"  # fem-incremental: what accepts
    dt_s: float | None = None  # the time step; None: the scene's

    def steps_for(self, scene: Scene, steps: int) -> int:
        """This variant's steps over the simulated time of ``steps`` of the scene's dt."""
        if self.dt_s is None:
            return steps
        return max(1, round(steps * scene.dt_s / self.dt_s))

    def apply(self, scene: Scene, steps: int) -> Scene:
        """The scene as this variant runs it (``steps`` of the variant's own dt)."""
        data = scene.model_dump()
        data["steps"] = steps
        if self.dt_s is not None:
            data["dt_s"] = self.dt_s
        if self.grid is not None:  # a uniform grid replaces a graded scene's resolution
            data["grid"], data["resolution"] = list(self.grid), None
        data["solver"] = {
            **data["solver"],
            "coupling": self.coupling,
            "incremental": self.incremental,
        }
        data["mechanics"] = {
            **data["mechanics"],
            "backend": self.backend,
            "rtol": self.rtol,
            "model": self.model,
            "guard_tolerance": self.guard_tolerance,
            "correction": self.correction,
            "full_every": self.full_every,
            "interval_tolerance": self.interval_tolerance,
            "guard": self.guard,
        }
        return scene_from_dict(data)

    def key(self, scene: Scene, steps: int) -> str:
        """A hash of everything that decides this variant's result (for resuming)."""
        text = json.dumps(
            [asdict(self), self.apply(scene, steps).model_dump(mode="json")], sort_keys=True
        )
        return hashlib.sha256(text.encode()).hexdigest()[:16]


DT_REFERENCE_S = 0.01
"""The time step of the reference a variant with its own dt is measured against."""


def reference_for(variant: Variant) -> Variant:
    """The FEM run at tight tolerance on the same grid, which the variant is measured against;
    for a variant with its own time step, at ``DT_REFERENCE_S`` (compared at common times)."""
    if variant.dt_s is not None:
        return Variant(
            name=f"reference-fem-{_grid_name(variant.grid)}-dt{DT_REFERENCE_S:g}",
            backend="fem",
            rtol=1e-10,
            grid=variant.grid,
            dt_s=DT_REFERENCE_S,
        )
    return Variant(
        name=f"reference-fem-{_grid_name(variant.grid)}",
        backend="fem",
        rtol=1e-10,
        grid=variant.grid,
    )


def _grid_name(grid: tuple[int, int, int] | None) -> str:
    return "scene-grid" if grid is None else "x".join(str(n) for n in grid)


NO_GUARD = 1e30
"""The guard tolerance of persistence without a guard: every prediction accepted, as the CNN's."""
NO_INTERVAL = 10000
"""...and without a full-solve interval (the scene's largest)."""


def default_variants(models: dict[str, str] | None = None) -> list[Variant]:
    """FEM at four tolerances, monolithic coupling, a coarser grid, incremental stepping (a full
    solve every 10 and every 50 steps; the energy guard), the time step (dt 0.01, 0.03 and 0.1 s,
    against a reference at dt 0.01 s), the baseline persistence ('previous': the last
    displacement Ritz-scaled; alone and with the patch, no guard, no interval: as the
    network's variants), plus the surrogates given.

    ``models`` maps variant names to model files, e.g. {"cnn-w16": "model.pt", "pgd-15": "pgd.npz"};
    a name starting with "cnn" runs the CNN backend: the network alone, with the patch
    correction, and with the patch and the guard at two tolerances; "pgd" the PGD one (also
    with online enrichment at an estimated strain-energy error of 10 %).
    """
    out = [
        Variant("fem-rtol1e-2", rtol=1e-2),
        Variant("fem-rtol1e-4", rtol=1e-4),
        Variant("fem-rtol1e-6", rtol=1e-6),
        Variant("fem-rtol1e-8", rtol=1e-8),
        Variant("fem-rtol1e-6-monolithic", rtol=1e-6, coupling="monolithic"),
        Variant("fem-coarse-rtol1e-6", rtol=1e-6, grid=(17, 17, 33)),
        Variant("fem-incremental", rtol=1e-6, incremental=True, correction="patch"),
        Variant(
            "fem-incremental-full50", rtol=1e-6, incremental=True, full_every=50,
            correction="patch",
        ),
        Variant(
            "fem-incremental-interval-fem", rtol=1e-6, incremental=True, correction="patch",
            interval_tolerance=0.0,
        ),
        Variant(
            "fem-incremental-energy", rtol=1e-6, incremental=True, correction="patch",
            guard="energy",
        ),
        Variant("fem-dt0.01", rtol=1e-6, dt_s=0.01),
        Variant("fem-dt0.03", rtol=1e-6, dt_s=0.03),
        Variant("fem-dt0.1", rtol=1e-6, dt_s=0.1),
        Variant(
            "fem-incremental-dt0.1", rtol=1e-6, incremental=True, correction="patch", dt_s=0.1
        ),
        Variant(
            "previous", incremental=True, correction="none", guard_tolerance=NO_GUARD,
            full_every=NO_INTERVAL,
        ),
        Variant(
            "previous+patch", incremental=True, correction="patch", guard_tolerance=NO_GUARD,
            full_every=NO_INTERVAL,
        ),
    ]  # fmt: skip
    for name, path in (models or {}).items():
        if name.startswith("cnn"):
            out.append(Variant(name, backend="cnn", model=path))
            out.append(Variant(f"{name}+patch", backend="cnn", model=path, correction="patch"))
            for tol, label in ((1e-2, "1e-2"), (1e-4, "1e-4")):
                out.append(
                    Variant(
                        f"{name}+patch+guard{label}", backend="cnn", model=path,
                        guard_tolerance=tol, correction="patch",
                    )
                )  # fmt: skip
        elif name.startswith("pgd"):
            out.append(Variant(name, backend="pgd", model=path))
            out.append(  # online enrichment when the strain-energy indicator exceeds 10 %
                Variant(f"{name}+enrich1e-1", backend="pgd", model=path, guard_tolerance=1e-1)
            )
    return out
