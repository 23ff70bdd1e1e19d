"""GET /v1/accuracy-cost serves the last accuracy-cost report, filtered by scene, behind auth."""

from __future__ import annotations

import json

from tests.service.conftest import LiveServer

ROW = {
    "scene": "fixed-electrode", "variant": "fem-rtol1e-6", "backend": "fem", "rtol": 1e-6,
    "grid": "33x33x65", "steps": 80, "step_median_s": 1.5, "step_p10_s": 1.2, "step_p90_s": 2.0,
    "mechanics_median_s": 1.1, "speedup_vs_reference": 1.4, "peak_rss_mb": 900.0,
    "se_error_max": 1e-7, "se_error_mean": 5e-8, "displacement_error_max": 1e-7,
    "cut_volume_error": 0.0, "crater_depth_error": 0.0, "error_slope_per_s": 0.0,
    "error_grows": False, "pareto": True, "failed": None, "model": None, "guard_tolerance": None,
}  # fmt: skip


def test_report_served_and_filtered(live: LiveServer, monkeypatch) -> None:
    monkeypatch.delenv("DIATHERMY_ACCURACY_REPORT", raising=False)
    folder = live.settings.data_dir / "accuracy-cost"
    folder.mkdir(parents=True, exist_ok=True)
    failed = {**ROW, "variant": "cnn-w8", "scene": "moving-electrode", "failed": "no model",
              "step_median_s": float("nan")}  # fmt: skip
    (folder / "report.json").write_text(
        json.dumps({"generated": "now", "steps": 80, "rows": [ROW, failed]})
    )
    with live.client() as api:
        r = api.get("/v1/accuracy-cost")
        assert r.status_code == 200, r.text
        body = r.json()
        assert [row["variant"] for row in body["rows"]] == ["fem-rtol1e-6", "cnn-w8"]
        assert body["rows"][1]["step_median_s"] is None and body["rows"][1]["failed"] == "no model"
        only = api.get("/v1/accuracy-cost", params={"scene": "fixed-electrode"}).json()
        assert [row["scene"] for row in only["rows"]] == ["fixed-electrode"]
    with live.client(token=None) as anon:
        assert anon.get("/v1/accuracy-cost").status_code == 401


def test_missing_report_is_404(live: LiveServer, monkeypatch, tmp_path) -> None:
    monkeypatch.setenv("DIATHERMY_ACCURACY_REPORT", str(tmp_path / "nope.json"))
    with live.client() as api:
        r = api.get("/v1/accuracy-cost")
        assert r.status_code == 404 and "accuracy-cost" in r.json()["message"]
