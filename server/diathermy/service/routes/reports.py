"""The accuracy-cost report, so a front end can offer the trade-off when it creates a session."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from fastapi import APIRouter, HTTPException
from pydantic import BaseModel

from diathermy.errors import SceneError
from diathermy.report.budget import PACKAGED_REPORT, load_report
from diathermy.service.deps import OwnerDep, StateDep
from diathermy.service.errors import AuthResponses
from diathermy.service.schemas import ErrorPublic

router = APIRouter(
    prefix="/v1/accuracy-cost",
    tags=["reports"],
    responses={**AuthResponses, 404: {"model": ErrorPublic, "description": "no report yet"}},
)


class AccuracyCostRow(BaseModel):
    """One measured way to run a scene: its cost per step and its error against FEM."""

    scene: str
    variant: str
    backend: str
    rtol: float
    grid: str
    steps: int
    step_median_s: float | None
    speedup_vs_reference: float | None
    peak_rss_mb: float | None
    se_error_max: float | None
    se_error_mean: float | None
    displacement_error_max: float | None
    cut_volume_error: float | None
    crater_depth_error: float | None
    error_grows: bool
    pareto: bool
    failed: str | None = None
    guard_tolerance: float | None = None


class AccuracyCostReport(BaseModel):
    """The last accuracy-cost report (``diathermy report accuracy-cost``)."""

    generated: str
    steps: int
    rows: list[AccuracyCostRow]


def report_path(data_dir: Path) -> Path:
    """$DIATHERMY_ACCURACY_REPORT, else DATA_DIR/accuracy-cost/report.json, else the packaged one."""
    env = os.environ.get("DIATHERMY_ACCURACY_REPORT")
    if env:
        return Path(env)
    local = data_dir / "accuracy-cost" / "report.json"
    return local if local.exists() else PACKAGED_REPORT


def _finite(row: dict[str, Any]) -> dict[str, Any]:
    """JSON has no NaN: failed rows carry None."""
    return {k: (None if isinstance(v, float) and v != v else v) for k, v in row.items()}


@router.get("", response_model=AccuracyCostReport)
def get_accuracy_cost(state: StateDep, _owner: OwnerDep, scene: str | None = None) -> Any:
    """Time per step vs strain-energy error of every measured variant (optionally of one scene)."""
    path = report_path(state.settings.data_dir)
    if not path.exists():
        raise HTTPException(404, "no accuracy-cost report has been run on this server yet")
    try:
        data = load_report(path)
    except SceneError as err:
        raise HTTPException(404, str(err)) from None
    rows = [_finite(r) for r in data["rows"] if scene is None or r["scene"] == scene]
    return {
        "generated": data.get("generated", ""),
        "steps": int(data.get("steps", 0)),
        "rows": rows,
    }
