"""A tiny run of benchmarks/convergence.py: its scene family, the sub-step crossing times
(convergence_runs.py), the tables of convergence_report.py and convergence_crater.py, and a
run -> report round trip on a coarse graded grid."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from tests.benchmarks.loading import load_benchmark


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    return load_benchmark("convergence")


@pytest.fixture(scope="module")
def report() -> ModuleType:
    return load_benchmark("convergence_report")


@pytest.fixture(scope="module")
def saved() -> ModuleType:
    return load_benchmark("convergence_runs")


@pytest.fixture(scope="module")
def crater() -> ModuleType:
    return load_benchmark("convergence_crater")


def test_crossing_is_exact_for_a_linear_rise(saved: ModuleType) -> None:
    t = np.array([0.03, 0.06, 0.09, 0.12])
    v = 310.0 + 600.0 * t  # passes 373.15 K at t = 0.10525 s, inside the 4th step
    assert saved.crossing(t, v, 373.15, 310.0) == pytest.approx(63.15 / 600.0, rel=1e-12)
    assert saved.crossing(t, v, 320.0, 310.0) == pytest.approx(10.0 / 600.0, rel=1e-12)
    assert math.isnan(saved.crossing(t, v, 1e4, 310.0))


def test_scene_family(bench: ModuleType) -> None:
    fine = bench.scene_for(0.8, moving=False, dt_s=0.015)
    assert fine.resolution.fine_m == pytest.approx(0.8e-3) and fine.dt_s == 0.015
    assert fine.electrodes[0].drive == "current_density"
    assert fine.resolution.depth_m == bench.builtin_scene("fixed-electrode").resolution.depth_m
    assert fine.resolution.deep_m is None  # the ladder's grids, whatever the scene ships
    assert fine.resolution.surface_m is None
    assert bench.scene_for(0.4, moving=False, surface_mm=0.1).resolution.surface_m == 1e-4
    deep = bench.scene_for(0.8, moving=False, deep_mm=40.0)
    assert deep.resolution.deep_m == pytest.approx(40e-3)
    assert bench.tag_of(0.8, False, deep_mm=40.0) == "fixed_0.8mm_deep40"
    uniform = bench.scene_for(0, moving=False)
    assert uniform.resolution is None and uniform.node_shape == (33, 33, 65)
    moving = bench.scene_for(None, moving=True)
    assert moving == bench.builtin_scene("moving-electrode")  # as shipped: 50 W, its grid
    assert bench.tag_of(0.8, False, 0.015) == "fixed_0.8mm_dt0.015"
    assert bench.tag_of(None, True) == "moving_default"
    assert bench.tag_of(0.4, False, contact="draped") == "fixed_0.4mm_draped"
    draped = bench.scene_for(0.4, moving=False, contact="draped")
    assert draped.electrodes[0].contact == "draped"
    fraction = bench.scene_for(0.4, moving=False, removal="fraction")
    assert fraction.level_set.removal == "fraction"
    assert bench.scene_for(0.4, moving=False).level_set.removal == "threshold"
    assert bench.tag_of(0.4, False, removal="fraction") == "fixed_0.4mm_fraction"
    assert bench.tag_of(0.4, False, removal="threshold") == "fixed_0.4mm"


def test_run_then_report(
    bench: ModuleType, report: ModuleType, tmp_path: Path, monkeypatch
) -> None:
    monkeypatch.setattr(bench, "RESULTS", tmp_path)
    monkeypatch.setattr(report, "RESULTS", tmp_path)
    out = bench.run(4.0, moving=False, seconds=0.09, wall_limit=60.0)
    d = np.load(out)
    assert d["time_s"].size == 3 and float(d["fine_mm"]) == 4.0
    assert d["w_front"].shape == d["cut_m3"].shape and float(d["kappa"]) > 0
    report.report()
    text = (tmp_path / "convergence.md").read_text()
    assert "| 4mm (" in text and "42.52 W" in text
    assert (tmp_path / "convergence.png").stat().st_size > 0


def test_drilling_rate_is_the_depth_slope(saved: ModuleType) -> None:
    t = np.arange(1, 61) * 0.03
    d = {"time_s": t, "depth_m": 1e-3 + 4e-3 * t}  # 4 mm/s
    assert saved.drilling_rate(d) == pytest.approx(4e-3, rel=1e-9)
    assert math.isnan(saved.drilling_rate({"time_s": t[:30], "depth_m": t[:30]}))  # ends early


def test_nonlocal_run_and_probe_then_report(
    bench: ModuleType, report: ModuleType, tmp_path: Path, monkeypatch
) -> None:
    """A non-local run and a removal-by-fraction run land in their own table beside the local,
    threshold run of their grid, not in the ladder; the floor probe's JSON becomes the table
    under the contact."""
    monkeypatch.setattr(bench, "RESULTS", tmp_path)
    monkeypatch.setattr(report, "RESULTS", tmp_path)
    bench.run(4.0, moving=False, seconds=0.09, wall_limit=60.0)
    out = bench.run(4.0, moving=False, seconds=0.09, wall_limit=60.0, length_mm=2.0)
    assert out.name == "convergence_fixed_4mm_l2.npz" and float(np.load(out)["length_mm"]) == 2.0
    out = bench.run(4.0, moving=False, seconds=0.09, wall_limit=60.0, removal="fraction")
    assert out.name == "convergence_fixed_4mm_fraction.npz"
    assert str(np.load(out)["removal"]) == "fraction"
    probe = bench.floor_probe(4.0, 3)
    records = json.loads(probe.read_text())["4"]
    assert len(records) == 3 and records[-1]["floor_t_k"] > 310.0
    report.report()
    text = (tmp_path / "convergence.md").read_text()
    assert "| 4 mm | 2 | flat | threshold |" in text  # the variants' table
    assert "| 4 mm | 0 | flat | fraction |" in text
    assert "4mm_l2 (" not in text and "4mm_fraction (" not in text  # not rows of the ladder


def test_ladder_compares_each_contact_at_the_finest_draped_end(
    crater: ModuleType, monkeypatch
) -> None:
    """The draped ladder and the flat one at the time the finest draped run reached, each
    against its own finest run; a run that stopped earlier shows - in the variants' table."""
    monkeypatch.setattr(crater, "summary", lambda d: {"cut_interp": 0.05})
    t_long, t_short = np.arange(1, 11) * 0.1, np.arange(1, 6) * 0.1

    def run(fine: float, scale: float, t: np.ndarray, contact: str) -> dict[str, np.ndarray]:
        return {
            "time_s": t,
            "cut_m3": scale * t * 1e-9,
            "depth_m": scale * t * 1e-3,
            "fine_mm": np.array(fine),
            "contact": np.array(contact),
        }

    runs = {
        "fixed_0.4mm": run(0.4, 0.8, t_long, "flat"),
        "fixed_0.2mm": run(0.2, 1.0, t_long, "flat"),
        "fixed_0.4mm_draped": run(0.4, 0.9, t_long, "draped"),
        "fixed_0.2mm_draped": run(0.2, 1.0, t_short, "draped"),
        "fixed_0.4mm_fraction": run(0.4, 0.7, t_long, "flat") | {"removal": np.array("fraction")},
    }
    keys = ["fixed_0.4mm_draped", "fixed_0.2mm_draped", "fixed_0.4mm_fraction"]
    text = "\n".join(crater.variant_lines(runs, keys))
    assert "cut 0.50 s mm^3" in text and "cut 1.00 s mm^3" in text
    assert "| 0.2 mm | 0 | draped | threshold | 0.50 |" in text and "| - | - | - |" in text
    # the removal variant beside the threshold run of its grid: 0.7 / 0.8 of its cut
    assert "| 0.4 mm | 0 | flat | fraction | 1.00 | 0.050 | 0.35 | 0.35 | 0.875 |" in text
    assert (
        "draped contact at t = 0.50 s, cut volume / depth against its 0.2 mm run: 0.4 mm 0.90 / 0.90"
        in text
    )
    assert (
        "flat contact at t = 0.50 s, cut volume / depth against its 0.2 mm run: 0.4 mm 0.80 / 0.80"
        in text
    )


def test_surface_refined_ladder_sits_beside_the_plain_runs(
    bench: ModuleType, report: ModuleType
) -> None:
    """Refined runs form their own ladder, each beside the plain run of its fine spacing, with
    ratios against the finest refined run at the times it reached; the tag names the surface."""
    assert bench.tag_of(0.4, False, surface_mm=0.1) == "fixed_0.4mm_s0.1"
    refined = bench.scene_for(0.4, moving=False, surface_mm=0.1)
    assert refined.resolution.surface_m == pytest.approx(1e-4)
    assert bench.scene_for(0.4, moving=False, surface_mm=0).resolution.surface_m is None
    t = np.arange(1, 101) * 0.03

    def run(fine: float, surface: float, scale: float, t100: float) -> dict[str, np.ndarray]:
        return {
            "time_s": t,
            "cut_m3": scale * t * 1e-9,
            "depth_m": t * 1e-3,
            "t_max_k": 310.15 + (373.15 - 310.15) * t / t100,
            "w_front": 1e3 * t / 0.06,  # reaches kappa = 1e3 at 0.06 s
            "kappa": np.array(1e3),
            "fine_mm": np.array(fine),
            "surface_mm": np.array(surface),
            "n_nodes": np.array(1000),
            "wall_s": np.ones_like(t),
            "power_w": np.full_like(t, 40.0),
            "p_max_pa": np.full_like(t, 2e5),
            "max_rss_mib": np.array(1.0),
        }

    runs = {
        "fixed_0.4mm": run(0.4, 0.0, 0.8, 0.03),
        "fixed_0.4mm_s0.1": run(0.4, 0.1, 0.95, 0.02),
        "fixed_0.2mm_s0.05": run(0.2, 0.05, 1.0, 0.02) | {"depth_mm": np.array(2.0)},
    }
    text = "\n".join(
        report._surface_lines(runs, ["fixed_0.4mm_s0.1", "fixed_0.2mm_s0.05"], ["fixed_0.4mm"])
    )
    assert "against the finest refined run (fixed_0.2mm_s0.05)" in text
    assert "cut 1.62 s mm^3 | / finest | cut 3 s mm^3 | / finest |" in text
    rows = [r for r in text.splitlines() if r.startswith("| 0.")]
    assert [r.split(" | ")[1] for r in rows] == ["0", "0.1", "0.05"]  # plain beside refined
    assert (
        "| 0.4 mm | 0 | 1000 | 0.0300 | 0.0600 | 1.000 | 1.30 | 0.800 | 2.40 | 0.800 | — |\n"
        in text
    )
    assert (
        "| 0.4 mm | 0.1 | 1000 | 0.0200 | 0.0600 | 1.000 | 1.54 | 0.950 | 2.85 | 0.950 | — |"
        in text
    )
    # the finest run's crater (1 mm/s) passes its 2 mm deep region in the step after 2 s
    assert (
        "| 0.2 mm | 0.05 | 1000 | 0.0200 | 0.0600 | 1.000 | 1.62 | 1.000 | 3.00 | 1.000 | 2.01 |"
        in text
    )
    assert "the finest refined run from 2.01 s" in text


def test_surface_cost_steps_both_grids_and_reports_the_ratio(
    bench: ModuleType, report: ModuleType, tmp_path: Path, monkeypatch
) -> None:
    """The cost comparison on a coarse grid: both grids step, the refined one has more nodes
    and its top cell, and the report states the ratio."""
    monkeypatch.setattr(bench, "RESULTS", tmp_path)
    monkeypatch.setattr(report, "RESULTS", tmp_path)
    out = bench.surface_cost(4.0, 1.0, warm=1, steps=2)
    c = json.loads(out.read_text())
    plain, refined = c["runs"]["plain"], c["runs"]["surface"]
    assert refined["nodes"] > plain["nodes"] and refined["surface_mm"] == 1.0
    assert plain["median_s"] > 0 and "electric" in refined["effects_median_s"]
    text = "\n".join(report._cost_lines(tmp_path))
    assert "Refined / plain: median step" in text and "| 1 |" in text


def test_a_deeper_reference_region_sits_beside_its_twin(
    bench: ModuleType, saved: ModuleType, crater: ModuleType
) -> None:
    """``run --depth-mm``: its own tag, kept out of the ladders, and shown beside the same run
    at the scene's depth with the 0.4 mm runs' crater against each."""
    assert bench.tag_of(0.2, False, surface_mm=0.05, depth_mm=16.0) == "fixed_0.2mm_s0.05_d16"
    assert bench.tag_of(0.2, False, surface_mm=0.05) == "fixed_0.2mm_s0.05"
    assert bench.scene_for(0.2, moving=False, depth_mm=16.0).resolution.depth_m == 0.016
    t = np.arange(1, 101) * 0.03

    def run(scale: float, region_mm: float) -> dict[str, np.ndarray]:
        return {
            "time_s": t,
            "cut_m3": scale * t * 1e-9,
            "depth_m": 5e-3 * t,  # 5 mm/s: passes 12 mm at 2.4 s, never 16 mm
            "depth_mm": np.array(region_mm),
            "n_nodes": np.array(1000),
        }

    runs = {
        "fixed_0.4mm": run(0.8, 12.0),
        "fixed_0.2mm_s0.05": run(1.0, 12.0),
        "fixed_0.2mm_s0.05_d16": run(1.25, 16.0),
    }
    assert not saved.standard_depth(runs["fixed_0.2mm_s0.05_d16"])
    text = "\n".join(crater.depth_lines(runs, ["fixed_0.2mm_s0.05_d16"]))
    assert (
        "| fixed_0.2mm_s0.05 | 12 | 1000 | 3.00 | 2.43 | 1.62 | 2.40 | 3.00 | 15.00 | 0.800 | — |"
        in text
    )
    assert (
        "| fixed_0.2mm_s0.05_d16 | 16 | 1000 | 3.00 | — | 2.02 | 3.00 | 3.75 | 15.00 | 0.640 | — |"
        in text
    )


def _linear_law_run(h_mm: float, a: float, b: float, power_w: float = 20.0) -> dict:
    """A synthetic run whose crater takes a + b h joules per mm^3 at every time."""
    t = np.arange(1, 101) * 0.03
    energy = power_w * t
    return {
        "time_s": t,
        "power_w": np.full(t.shape, power_w),
        "dt_s": np.array(0.03),
        "cut_m3": energy / (a + b * h_mm) * 1e-9,
        "depth_m": 4e-3 * t,
        "fine_mm": np.array(h_mm),
        "depth_mm": np.array(12.0),
        "n_nodes": np.array(1000),
        "wall_s": np.full(t.shape, 0.5),
        "t_max_k": 300.0 + 100.0 * t,
        "w_front": 1e4 * t,
        "kappa": np.array(1e5),
        "p_max_pa": np.full(t.shape, 2e5),
        "max_rss_mib": np.array(100.0),
    }


def test_energy_per_removed_volume_recovers_a_linear_law(
    saved: ModuleType, crater: ModuleType
) -> None:
    """The Joule energy is the steps' powers times dt, and the fit over the spacings gives back
    the law the runs were made with, first order."""
    runs = {f"fixed_{h:g}mm": _linear_law_run(h, 0.95, 1.1) for h in (0.8, 0.4, 0.2)}
    assert saved.joule_energy(runs["fixed_0.4mm"], 1.62) == pytest.approx(20.0 * 1.62)
    text = "\n".join(crater.energy_lines(runs, sorted(runs)))
    assert f"| 3 | fixed_0.4mm | 0.4 | 12 | 60.0 | {60 / 1.39:.1f} | 1.390 |" in text
    assert (
        "J/mm^3 = 0.950 + 1.100 h (h -> 0: 0.950; b / a = 1.16 per mm), observed order 1.00" in text
    )
    assert f"the 0.4 mm grid removes {100 * 0.95 / 1.39:.0f} %" in text


def test_a_cell_height_of_its_own_is_its_own_run(
    bench: ModuleType, saved: ModuleType, crater: ModuleType
) -> None:
    """``run --fine-z-mm``: the scene's cell height, its own tag, out of the cubic ladders, and
    beside the cubic run of the same width."""
    scene = bench.scene_for(0.8, moving=False, fine_z_mm=0.2)
    assert scene.resolution.fine_spacing_m == pytest.approx((0.8e-3, 0.8e-3, 0.2e-3))
    assert bench.tag_of(0.8, False, fine_z_mm=0.2) == "fixed_0.8mm_z0.2"
    assert bench.tag_of(0.8, False, fine_z_mm=0.8) == "fixed_0.8mm"
    cubic = _linear_law_run(0.8, 0.95, 1.1)
    tall = {**_linear_law_run(0.8, 0.95, 1.1), "fine_z_mm": np.array(0.2)}
    tall["depth_m"] = 2 * tall["depth_m"]  # twice as deep, the same volume
    assert saved.cubic(cubic) and not saved.cubic(tall)
    runs = {"fixed_0.8mm": cubic, "fixed_0.8mm_z0.2": tall}
    text = "\n".join(crater.axis_lines(runs, ["fixed_0.8mm_z0.2"]))
    assert "at t = 3.00 s" in text
    rows = [line for line in text.splitlines() if line.startswith("| fixed_")]
    assert [r.split(" | ")[0:3] for r in rows] == [
        ["| fixed_0.8mm", "0.8", "0.8"],
        ["| fixed_0.8mm_z0.2", "0.8", "0.2"],
    ]
    assert "| 12.00 |" in rows[0] and "| 24.00 |" in rows[1]  # depth at 3 s, mm


def test_main_job_reports_each_effect_over_the_cutting_steps(
    bench: ModuleType, report: ModuleType, tmp_path: Path, monkeypatch
) -> None:
    """``main-job``'s record of one grid (a tiny graded scene for ``default``): the cutting
    steps' median per effect, and the report's table of them."""
    from diathermy.scene import Resolution
    from tests.engine.scenes import tiny_scene

    res = Resolution(fine_m=0.5e-3, max_cell_m=2e-3, margin_m=1e-3, depth_m=1.5e-3)
    monkeypatch.setattr(bench, "builtin_scene", lambda name: tiny_scene(resolution=res))
    job = bench._main_job(False, 20)
    assert job["graded"] and job["cutting_steps"] > 0
    med = job["cutting_effects_median_s"]
    assert {"electric", "thermal", "mechanics"} <= set(med) and med["mechanics"] > 0
    (tmp_path / "convergence_main_job.json").write_text(json.dumps([job, job]))
    text = "\n".join(report._main_job_lines(tmp_path))
    assert "Median time of each effect over the cutting steps" in text
    assert f"{med['mechanics']:.3f} |" in text
