"""The accuracy budget: the cheapest measured way to run a scene within a strain-energy error."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from diathermy.errors import SceneError
from diathermy.scene import Scene, scene_from_dict


def load_report(path: str | Path) -> dict[str, Any]:
    """The JSON an accuracy-cost report wrote (``report.json``)."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        raise SceneError(f"accuracy report {path} cannot be read: {err}") from None
    if not isinstance(data, dict) or not isinstance(data.get("rows"), list):
        raise SceneError(f"accuracy report {path} is not a diathermy accuracy-cost report")
    return data


def cheapest_within(
    report: dict[str, Any],
    *,
    scene: str,
    max_strain_energy_error: float,
    grid: str | None = None,
    dt_s: float = 0.03,
) -> dict[str, Any]:
    """The measured row of ``scene`` (optionally on ``grid``) whose max error meets the budget
    at the least wall time per simulated second (rows without their own dt ran at ``dt_s``)."""
    rows = [
        r for r in report["rows"]
        if r["scene"] == scene and not r.get("failed") and (grid is None or r["grid"] == grid)
    ]  # fmt: skip
    if not rows:
        raise SceneError(
            f"accuracy_budget: the accuracy report has no measurements for scene {scene!r}"
            + (f" on grid {grid}" if grid is not None else "")
        )
    # a run that never reached the mechanics has error 0 by construction: no evidence at all
    rows = [r for r in rows if r.get("compared_steps", 1) > 0]
    if not rows:
        raise SceneError(
            f"accuracy_budget: the accuracy report's runs of {scene!r} never reached the "
            "mechanics (0 compared steps), so they say nothing about its error; measure it "
            "with more steps (diathermy report accuracy-cost --steps N)"
        )
    ok = [r for r in rows if r["se_error_max"] <= max_strain_energy_error]
    if not ok:
        best = min(r["se_error_max"] for r in rows)
        raise SceneError(
            f"accuracy_budget.max_strain_energy_error: no measured variant of {scene!r} reaches "
            f"{max_strain_energy_error:g} (best measured: {best:.3g})"
        )
    return min(ok, key=lambda r: r["step_median_s"] / (r.get("dt_s") or dt_s))


PACKAGED_REPORT = Path(__file__).with_name("data") / "accuracy_cost.json"
"""The report measured for this release (``diathermy report accuracy-cost --install``)."""


def resolve_accuracy_budget(scene: Scene, report_path: str | Path | None = None) -> Scene:
    """The scene with the cheapest measured mechanics variant meeting its ``accuracy_budget``.

    The report comes from ``report_path`` (the entry points pass ``$DIATHERMY_ACCURACY_REPORT``),
    else the one packaged with diathermy. A scene without a budget is returned unchanged.
    """
    if scene.accuracy_budget is None:
        return scene
    path = report_path or PACKAGED_REPORT
    grid = "x".join(str(n) for n in scene.node_shape)
    row = cheapest_within(
        load_report(path),
        scene=scene.name,
        max_strain_energy_error=scene.accuracy_budget.max_strain_energy_error,
        grid=grid,
        dt_s=scene.dt_s,
    )
    data = scene.model_dump()
    if row.get("dt_s") and row["dt_s"] != scene.dt_s:  # a larger step met the budget
        data["steps"] = max(1, round(scene.steps * scene.dt_s / row["dt_s"]))
        data["dt_s"] = row["dt_s"]
    data["mechanics"].update(
        backend=row["backend"], rtol=row["rtol"], guard_tolerance=row.get("guard_tolerance"),
        correction=row.get("correction", "none"),  # reports before the patch: the network's u
        model=row.get("model") if row.get("model") and Path(row["model"]).exists() else None,
    )  # fmt: skip
    if row["backend"] == "fem":  # rows measured before issue #25 solved in full
        data["mechanics"]["full_every"] = row.get("full_every", 10)
        # rows measured before the interval's tolerance existed solved it to the FEM rtol
        data["mechanics"]["interval_tolerance"] = row.get("interval_tolerance", 0.0)
        data["mechanics"]["guard"] = row.get("guard", "auto")
        data["solver"]["incremental"] = bool(row.get("incremental", False))
        if row["variant"] != "previous":  # persistence patched but alone: rows before #22 said
            data["mechanics"]["correction"] = "patch"  # "none" for fem and patched all the same
    data["accuracy_budget"] = None  # resolved: the chosen variant is now explicit
    return scene_from_dict(data)
