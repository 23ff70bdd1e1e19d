"""The engine on a graded grid (scene.resolution): it heats, boils and cuts, closes its energy
balance, restores bit for bit, and its run file, checkpoint and VTU carry the node coordinates."""

from __future__ import annotations

import meshio
import numpy as np
import pytest

from diathermy.engine.run import run_scene
from diathermy.engine.runfile import read_run
from diathermy.engine.simulation import Simulation
from diathermy.errors import SceneError
from diathermy.mesh import grid_from_attrs
from diathermy.scene import Resolution
from tests.engine.scenes import tiny_scene

RES = Resolution(fine_m=0.5e-3, max_cell_m=2e-3, margin_m=1e-3, depth_m=1.5e-3)


def graded_scene(**overrides):
    return tiny_scene(resolution=RES, **overrides)


def test_graded_scene_meshes_fine_under_the_electrode():
    scene = graded_scene()
    grid = scene.node_grid()
    assert not grid.is_uniform and scene.node_shape == grid.shape
    x, y, z = grid.axes()
    # the contact (radius 1.17 mm) plus 1 mm margin lies in cells of at most 0.5 mm
    for a, c, half in ((x, 0.01, 2.17e-3), (y, 0.005, 2.17e-3)):
        inside = (a[:-1] >= c - half - 1e-12) & (a[1:] <= c + half + 1e-12)
        assert np.diff(a)[inside].max() <= 0.5e-3 + 1e-12
    assert np.diff(z)[z[:-1] >= 0.01 - 1.5e-3 - 1e-12].max() <= 0.5e-3 + 1e-12
    assert max(np.diff(a).max() for a in (x, y, z)) <= 2e-3 + 1e-12


@pytest.mark.parametrize("surface_m", [None, 0.125e-3])
def test_graded_run_cuts_and_balances_energy(surface_m):
    """Also on a grid refined toward the surface (``resolution.surface_m``: 4:1 cells at the
    top)."""
    res = RES.model_copy(update={"surface_m": surface_m})
    sim = Simulation(tiny_scene(resolution=res))
    if surface_m is not None:
        top = np.diff(sim.grid.axes()[2])[-1]  # at most surface_m: 1.5 mm of region is short
        assert 0.5 * surface_m < top <= surface_m * (1 + 1e-9)
    reports = sim.run(25)
    cut = [r.cut_volume_m3 for r in reports]
    assert cut[-1] > 0 and all(b >= a for a, b in zip(cut, cut[1:], strict=False))
    assert 0 < reports[-1].crater_depth_m < 0.01
    e = reports[-1].energy
    assert e["latent_stored"] > 0
    assert abs(e["imbalance"]) <= 1e-3 * e["joule_in"]
    (key,) = sim.ctx.contacts.entries
    assert key[2] < sim.ctx.top_z  # the disk follows the crater floor on the graded axes


@pytest.mark.parametrize("history", [0, 3])
def test_graded_checkpoint_restores_bit_for_bit(tmp_path, history):
    """Also with the window's history (``mechanics.window_history``), saved with the state."""
    sim = Simulation(graded_scene(mechanics={"window_history": history}))
    sim.run(12)
    assert len(sim.ctx.mechanics.history) == history
    path = sim.save_checkpoint(tmp_path / "c.h5")
    saved = read_grid_attrs(path)
    assert all(np.array_equal(a, b) for a, b in zip(saved.axes(), sim.grid.axes(), strict=True))
    sim.run(5)
    back = Simulation.load_checkpoint(path)
    back.run(5)
    for name, arr in sim.state.arrays.items():
        assert np.array_equal(arr, back.state.arrays[name]), name


def test_a_corrupt_polish_window_in_a_checkpoint_is_refused(tmp_path):
    import h5py

    from diathermy.errors import CheckpointError

    sim = Simulation(graded_scene())
    sim.run(12)
    assert sim.ctx.mechanics.window is not None  # the windowed polish's, saved with the state
    path = sim.save_checkpoint(tmp_path / "c.h5")
    with h5py.File(path, "a") as f:
        box = f["solver/mechanics_window_box"][()]
        del f["solver/mechanics_window_box"]
        f["solver/mechanics_window_box"] = box[:2]
    with pytest.raises(CheckpointError, match="mechanics window"):
        Simulation.load_checkpoint(path)


def test_with_the_history_the_strain_energy_is_the_answers():
    """The history moves the answer everywhere: its strain energy is recomputed, not the
    Ritz-scaled last one updated on the window's tets."""
    from diathermy.physics.strain_energy import strain_energy_density

    # a loose guard, so that the window's answer stands without global iterations: the path
    # where the strain energy of the Ritz-scaled last answer would otherwise be updated
    sim = Simulation(graded_scene(mechanics={"window_history": 3, "energy_tolerance": 0.05}))
    used = []
    for _ in range(20):
        x = sim.step().effects["mechanics"].extra
        used.append(x.get("window_history", 0) > 0 and x.get("polish_iterations") == 0)
    assert any(used)
    be = sim.ctx.mechanics.fem
    solver = be.solver
    W = strain_energy_density(
        sim.ctx.disc.geom.grads, sim.ctx.disc.mesh.tets, sim.state["displacement"],
        solver.youngs_modulus_pa, solver.poisson_ratio,
    )  # fmt: skip
    np.testing.assert_allclose(sim.state["strain_energy"], W, rtol=1e-9, atol=1e-12 * W.max())


def test_a_corrupt_window_history_in_a_checkpoint_is_refused(tmp_path):
    import h5py

    from diathermy.errors import CheckpointError

    sim = Simulation(graded_scene(mechanics={"window_history": 2}))
    sim.run(12)
    path = sim.save_checkpoint(tmp_path / "c.h5")
    for bad in ("shape", "nan"):
        with h5py.File(path, "a") as f:
            h = f["solver/mechanics_history"][()]
            del f["solver/mechanics_history"]
            f["solver/mechanics_history"] = h[:, :-1] if bad == "shape" else h * np.nan
        with pytest.raises(CheckpointError, match="mechanics history"):
            Simulation.load_checkpoint(path)
        path = sim.save_checkpoint(tmp_path / "c.h5")
    # a scene that keeps less history than was saved takes the newest
    back = Simulation.load_checkpoint(
        path,
        scene=lambda s: s.model_copy(
            update={"mechanics": s.mechanics.model_copy(update={"window_history": 1})}
        ),
    )
    assert len(back.ctx.mechanics.history) == 1
    assert np.array_equal(back.ctx.mechanics.history[0], sim.ctx.mechanics.history[0])


def read_grid_attrs(path):
    import h5py

    with h5py.File(path, "r") as f:
        return grid_from_attrs(dict(f.attrs))


def test_run_file_and_vtu_carry_the_node_coordinates(tmp_path):
    scene = graded_scene(steps=2, effects=["electric", "thermal"])
    run_scene(scene, out=tmp_path / "r.h5", vtu_dir=tmp_path / "vtu", progress=False)
    run = read_run(tmp_path / "r.h5")
    assert "spacing_m" not in run["attrs"]
    back, grid = grid_from_attrs(run["attrs"]), scene.node_grid()
    assert back.shape == grid.shape
    assert all(np.array_equal(a, b) for a, b in zip(back.axes(), grid.axes(), strict=True))
    assert run["fields"]["temperature"].shape == (2, *grid.shape)
    (vtu,) = sorted((tmp_path / "vtu").glob("*.vtu"))[-1:]
    assert np.allclose(meshio.read(vtu).points, grid.points())


def test_uniform_scene_keeps_its_attributes(tmp_path):
    scene = tiny_scene(steps=1, effects=["electric"])
    assert "resolution" not in scene.model_dump()  # run files and checkpoints byte-identical
    run_scene(scene, out=tmp_path / "u.h5", progress=False)
    attrs = read_run(tmp_path / "u.h5")["attrs"]
    assert "node_x_m" not in attrs and np.allclose(attrs["spacing_m"], scene.node_grid().spacing_m)


@pytest.mark.parametrize("backend", ["cnn", "pgd"])
def test_surrogates_refuse_a_graded_grid(backend):
    with pytest.raises(SceneError, match="runs on uniform grids only"):
        Simulation(graded_scene(mechanics={"backend": backend, "model": "x.pt"})).step()


def test_dataset_samples_refuse_a_graded_scene(tmp_path):
    from diathermy.datagen.engine_samples import write_scene_samples

    with pytest.raises(ValueError, match="tiny use a graded grid"):
        write_scene_samples([graded_scene()], tmp_path / "d.h5", n_steps=1)


def test_reports_say_when_the_cut_leaves_the_fine_region(tmp_path):
    """The region is 1.5 mm deep; the crater passes it by step ~16. Each report gives how far the
    cut's deepest node lies beyond it: below the crater's floor (which lies between that node and
    the next one down, at most one 2 mm cell away), 0 while the floor is within the region."""
    scene = graded_scene(steps=25)
    summary = run_scene(scene, out=tmp_path / "r.h5", progress=False)
    reports = read_run(tmp_path / "r.h5")["reports"]
    depth_m = RES.depth_m
    beyond = [r["beyond_fine_region_m"]["cut"] for r in reports]
    assert beyond[0] == 0.0 and beyond[-1] > 0
    for r, b in zip(reports, beyond, strict=True):
        floor = r["crater_depth_m"] - depth_m  # the crater floor below the region, m
        assert b <= max(floor, 0.0) + 1e-12  # the deepest cut node lies above the floor...
        if b > 0:
            assert floor - b < RES.max_cell_m  # ...and the floor above the next node down
    first = next(r["time_s"] for r, b in zip(reports, beyond, strict=True) if b > 0)
    assert summary.left_fine_region["cut"] == (first, max(beyond))
    (line,) = summary.warnings()
    assert "cut from t = " in line and "resolution.depth_m" in line


def test_a_uniform_grid_has_no_fine_region_to_leave(tmp_path):
    summary = run_scene(tiny_scene(steps=20), out=tmp_path / "u.h5", progress=False)
    assert summary.cut_volume_m3 > 0  # it cut, and there is no region to report against
    assert read_run(tmp_path / "u.h5")["reports"][-1]["beyond_fine_region_m"] == {}
    assert summary.left_fine_region == {} and summary.warnings() == []


def test_an_electrode_moved_off_the_fine_region_is_reported():
    """A client drags the electrode 3.8 mm past the region's side (x <= 12.17 mm): the crater it
    digs there lies in coarse cells, and the reports say so from the first cut on."""
    sim = Simulation(graded_scene())
    sim.set_electrode("active", position_m=(0.016, 0.005))
    reports = sim.run(20)
    cutting = [r for r in reports if r.cut_volume_m3 > 0]
    assert cutting
    assert all(r.beyond_fine_region_m["cut"] > 2e-3 for r in cutting)
    assert all(r.beyond_fine_region_m["cut"] == 0.0 for r in reports if r.cut_volume_m3 == 0)


def test_a_coagulation_lesion_past_the_fine_region_is_reported():
    """No vapor, no cut: the Arrhenius lesion (Omega >= 1) is what a coagulation scene is for,
    and it too is reported once it spreads past the 1.5 mm deep region."""
    sim = Simulation(graded_scene(effects=["electric", "thermal", "thermal_damage"], steps=45))
    reports = sim.run(45)
    beyond = [r.beyond_fine_region_m for r in reports]
    assert all(b["cut"] == 0.0 and b["vapor"] == 0.0 for b in beyond)
    assert beyond[0]["lesion"] == 0.0 and beyond[-1]["lesion"] > 0.0
    omega = sim.state["thermal_damage"]
    z = sim.disc.mesh.points[:, 2]
    deepest = sim.ctx.top_z - z[omega >= 1.0].min()  # the lesion's deepest node below the top
    assert beyond[-1]["lesion"] >= deepest - RES.depth_m - 1e-12
