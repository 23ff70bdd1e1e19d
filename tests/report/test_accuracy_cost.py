"""A tiny accuracy-cost report end to end: its table agrees with the run files it came from."""

from __future__ import annotations

import csv
import json
from dataclasses import asdict

import numpy as np
import pytest

from diathermy.errors import SceneError
from diathermy.physics.strain_energy import relative_strain_energy_error
from diathermy.report.accuracy_cost import accuracy_cost_report, common_steps
from diathermy.report.budget import cheapest_within, resolve_accuracy_budget
from diathermy.report.measure import load_fields
from diathermy.report.variants import Variant
from diathermy.scene import AccuracyBudget
from tests.engine.scenes import tiny_scene


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("acc")
    scene = tiny_scene()
    variants = [Variant("fem-rtol1e-2", rtol=1e-2), Variant("fem-rtol1e-6", rtol=1e-6)]
    rows = accuracy_cost_report([scene], variants, steps=20, out=out, progress=False)
    return scene, rows, out


def test_table_matches_run_files(report):
    scene, rows, out = report
    assert [r.variant for r in rows] == ["fem-rtol1e-2", "fem-rtol1e-6"]
    runs = {p.name.split("--")[1]: p for p in (out / "runs").glob("*.h5")}
    refs = [name for name in runs if name.startswith("reference-fem-")]
    assert len(refs) == 1, refs  # one reference per grid, shared by the variants on that grid
    W_ref, _ = load_fields(runs[refs[0]])
    for row in rows:
        assert row.failed is None
        W, _ = load_fields(runs[row.variant])
        errs = [
            relative_strain_energy_error(W[i].astype(float), W_ref[i].astype(float))
            for i in range(W.shape[0])
            if W_ref[i].any()
        ]
        assert errs, "the tiny scene must reach the mechanics"
        assert row.se_error_max == pytest.approx(max(errs))
        assert row.se_error_mean == pytest.approx(np.mean(errs))
        rec = json.loads((runs[row.variant].with_suffix(".json")).read_text())
        assert row.step_median_s == pytest.approx(np.median(rec["step_s"]))
    loose, tight = rows
    assert loose.se_error_max > tight.se_error_max  # a looser tolerance costs accuracy
    with open(out / "report.csv") as f:
        assert len(list(csv.DictReader(f))) == 2
    md = (out / "report.md").read_text()
    assert md.count("| tiny |") == 2 and "published, not measured here" in md
    assert (out / "error_vs_cost.png").stat().st_size > 0 and (out / "error_vs_time.png").exists()


def test_resume_does_not_rerun(report):
    scene, rows, out = report
    before = {p: p.stat().st_mtime_ns for p in (out / "runs").glob("*.h5")}
    again = accuracy_cost_report(
        [scene], [Variant("fem-rtol1e-6", rtol=1e-6)], steps=20, out=out, progress=False
    )
    assert again[0].se_error_max == rows[1].se_error_max
    assert {p: p.stat().st_mtime_ns for p in (out / "runs").glob("*.h5")} == before


def test_accuracy_budget_picks_cheapest_meeting_it(report, tmp_path):
    scene, rows, out = report
    data = {"rows": [asdict(r) for r in rows]}
    (tmp_path / "report.json").write_text(json.dumps(data))
    loose, tight = rows
    budget = (loose.se_error_max + tight.se_error_max) / 2
    pick = cheapest_within(data, scene="tiny", max_strain_energy_error=budget)
    assert pick["variant"] == "fem-rtol1e-6"
    pick = cheapest_within(data, scene="tiny", max_strain_energy_error=1.0)
    assert pick["step_median_s"] == min(r.step_median_s for r in rows if r.se_error_max <= 1.0)
    with pytest.raises(SceneError, match="no measured variant"):
        cheapest_within(data, scene="tiny", max_strain_energy_error=tight.se_error_max / 10)
    budgeted = tiny_scene(accuracy_budget=AccuracyBudget(max_strain_energy_error=budget))
    resolved = resolve_accuracy_budget(budgeted, tmp_path / "report.json")
    assert resolved.mechanics.rtol == 1e-6 and resolved.accuracy_budget is None
    with pytest.raises(SceneError, match="cannot be read"):
        resolve_accuracy_budget(budgeted, out / "missing.json")


def test_graded_scenes_are_put_on_a_uniform_grid_or_refused(report, tmp_path):
    """The report compares uniform grids: a graded scene is refused by name, a variant's grid
    replaces the scene's resolution, and a budget looks rows up by the grid the scene meshes."""
    graded = tiny_scene(resolution={"fine_m": 2e-3, "max_cell_m": 5e-3})
    with pytest.raises(SceneError, match="tiny.*graded"):
        accuracy_cost_report([graded], [Variant("fem")], steps=1, out=tmp_path, progress=False)
    assert Variant("coarse", grid=(5, 5, 9)).apply(graded, 3).node_shape == (5, 5, 9)
    data = {"rows": [asdict(r) for r in report[1]]}
    budgeted = graded.model_copy(
        update={"accuracy_budget": AccuracyBudget(max_strain_energy_error=1.0)}
    )
    (tmp_path / "report.json").write_text(json.dumps(data))
    shape = "x".join(map(str, graded.node_shape))
    with pytest.raises(SceneError, match=f"no measurements for scene 'tiny' on grid {shape}"):
        resolve_accuracy_budget(budgeted, tmp_path / "report.json")


def test_accuracy_budget_ignores_runs_that_never_reached_the_mechanics(report):
    _, rows, _ = report
    measured = [asdict(r) for r in rows]
    # a cheaper variant whose run never solved the mechanics: error 0 by construction only
    vacuous = {**measured[0], "variant": "cnn-w8", "compared_steps": 0, "se_error_max": 0.0,
               "step_median_s": 0.0}  # fmt: skip
    data = {"rows": [*measured, vacuous]}
    pick = cheapest_within(data, scene="tiny", max_strain_energy_error=1.0)
    assert pick["variant"] != "cnn-w8" and pick["compared_steps"] > 0
    with pytest.raises(SceneError, match="never reached the mechanics"):
        cheapest_within({"rows": [vacuous]}, scene="tiny", max_strain_energy_error=1.0)


def test_common_steps_match_times_across_time_steps():
    t_ref = 0.01 * np.arange(1, 61)  # the reference at dt 0.01 s
    t = np.cumsum(np.full(20, 0.03))  # a variant at 0.03 s, its times accumulated step by step
    j = common_steps(t, t_ref)
    assert np.array_equal(j, np.arange(2, 60, 3))
    assert np.array_equal(common_steps([0.005, 0.6, 0.7], t_ref), [-1, 59, -1])
    assert np.array_equal(common_steps([0.1], []), [-1])


@pytest.fixture(scope="module")
def dt_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("acc-dt")
    scene = tiny_scene()
    variants = [Variant("fem-dt0.03", dt_s=0.03), Variant("fem-dt0.09", dt_s=0.09)]
    rows = accuracy_cost_report([scene], variants, steps=18, out=out, progress=False)
    return scene, rows, out


def test_time_step_variants_are_measured_against_dt_001_at_common_times(dt_report):
    """A variant with its own dt runs the same simulated time and is compared with FEM at
    dt 0.01 s at the times both have; a larger step costs accuracy, per simulated second less."""
    scene, rows, out = dt_report
    runs = {p.name.split("--")[1]: p for p in (out / "runs").glob("*.h5")}
    ref_name = next(n for n in runs if n.startswith("reference-fem-") and n.endswith("dt0.01"))
    ref = json.loads(runs[ref_name].parent.joinpath(runs[ref_name].stem + ".json").read_text())
    assert len(ref["time_s"]) == round(18 * scene.dt_s / 0.01)
    W_ref, _ = load_fields(runs[ref_name])
    for row, dt in zip(rows, (0.03, 0.09), strict=True):
        assert row.failed is None and row.dt_s == dt
        path = runs[row.variant]
        rec = json.loads(path.parent.joinpath(path.stem + ".json").read_text())
        assert rec["time_s"][-1] == pytest.approx(ref["time_s"][-1])  # the same simulated time
        W, _ = load_fields(runs[row.variant])
        j = common_steps(np.asarray(rec["time_s"]), np.asarray(ref["time_s"]))
        assert np.all(j >= 0)  # 0.03 and 0.09 are multiples of 0.01
        errs = [
            relative_strain_energy_error(W[i].astype(float), W_ref[k].astype(float))
            for i, k in enumerate(j)
            if W_ref[k].any()
        ]
        assert errs and row.compared_steps == len(errs)
        assert row.se_error_max == pytest.approx(max(errs))
        cut_ref = ref["cut_volume_m3"][-1]  # the crater against the dt 0.01 s reference too
        if cut_ref > 0:
            want = abs(rec["cut_volume_m3"][-1] - cut_ref) / cut_ref
            assert row.cut_volume_error == pytest.approx(want)
    fine, coarse = rows
    assert coarse.se_error_mean > fine.se_error_mean > 0  # the time step's own error


def test_accuracy_budget_may_choose_a_larger_time_step(dt_report, tmp_path):
    scene, rows, _ = dt_report
    fast = {**asdict(rows[1]), "step_median_s": asdict(rows[0])["step_median_s"]}
    data = {"rows": [asdict(rows[0]), fast]}  # same wall per step, 3x the simulated time
    pick = cheapest_within(data, scene="tiny", max_strain_energy_error=1.0, dt_s=scene.dt_s)
    assert pick["dt_s"] == 0.09
    (tmp_path / "report.json").write_text(json.dumps(data))
    budgeted = tiny_scene(accuracy_budget=AccuracyBudget(max_strain_energy_error=1.0))
    resolved = resolve_accuracy_budget(budgeted, tmp_path / "report.json")
    assert resolved.dt_s == 0.09
    assert resolved.steps * resolved.dt_s == pytest.approx(budgeted.steps * budgeted.dt_s, 0.05)
