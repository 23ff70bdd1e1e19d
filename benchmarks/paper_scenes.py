"""The paper's scenes on the default grid: heating, pressure, energy, crater (one command).

    python benchmarks/paper_scenes.py                       # fixed + moving, then the report
    python benchmarks/paper_scenes.py run --scene fixed-electrode --steps 400 --wall-limit 900
    python benchmarks/paper_scenes.py report                # tables and figures from saved runs

``run`` steps a built-in scene (grid and steps configurable), stops early at ``--wall-limit``
seconds, and saves per-step records (``benchmarks/results/paper_scenes_<scene>.npz``) plus a
checkpoint of the last state (``runs/paper_scenes_<scene>.h5``, also used by
``benchmarks/effects.py``). ``report`` writes ``benchmarks/results/paper_scenes.md``,
``crater.png`` (cross-section through the electrode) and ``crater_vs_time.png``.

BLAS runs single-threaded (set before numpy loads): on this shared 2-core machine threaded
OpenBLAS made pyamg's dense coarse solve up to 40x slower.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "server"))

from diathermy.engine.electrodes import electrode_pose  # noqa: E402
from diathermy.engine.simulation import Simulation  # noqa: E402
from diathermy.physics.eos import saturation_pressure  # noqa: E402
from diathermy.scene import builtin_scene  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
RUNS = ROOT / "runs"
T_100C = 373.15


def contact_node(sim: Simulation, x: float, y: float) -> int:
    """Flat index of the top-surface node nearest (x, y) in m."""
    g = sim.grid
    xs, ys, _ = g.axes()
    i, j = int(np.abs(xs - x).argmin()), int(np.abs(ys - y).argmin())
    return ((g.nz - 1) * g.ny + j) * g.nx + i


def run_scene(name: str, grid: tuple[int, int, int], steps: int, wall_limit: float) -> Path:
    """Step scene ``name`` and save its per-step records; returns the records' path."""
    scene = builtin_scene(name).on_uniform_grid(grid).model_copy(update={"steps": steps})
    sim = Simulation(scene)
    p0 = sim.tissue.p_atm_pa
    rec: dict[str, list[float]] = {
        k: []
        for k in (
            "time_s",
            "wall_s",
            "power_w",
            "t_max_k",
            "t_contact_k",
            "p_max_pa",
            "u_max_m",
            "w_max_j_per_m3",
            "crater_depth_m",
            "cut_volume_m3",
            "joule_in_j",
            "sensible_j",
            "latent_j",
            "convective_j",
            "imbalance_j",
        )
    }
    effect_wall: dict[str, list[float]] = {e: [] for e in sim.effects}
    p_above: list[np.ndarray] = []
    t0 = time.perf_counter()
    for _ in range(steps):
        rep = sim.step()
        el = sim.scene.electrodes[0]
        x, y = electrode_pose(el, rep.time_s, sim.state.overrides.get(el.name)).position_m
        T = sim.state["temperature"]
        p = sim.state["pressure"]
        e = rep.energy
        for k, v in (
            ("time_s", rep.time_s),
            ("wall_s", rep.wall_s),
            ("power_w", rep.delivered_power_w),
            ("t_max_k", rep.max_temperature_k),
            ("t_contact_k", float(T[contact_node(sim, x, y)])),
            ("p_max_pa", rep.max_pressure_pa),
            ("u_max_m", rep.max_displacement_m),
            ("w_max_j_per_m3", rep.max_strain_energy_j_per_m3),
            ("crater_depth_m", rep.crater_depth_m),
            ("cut_volume_m3", rep.cut_volume_m3),
            ("joule_in_j", e["joule_in"]),
            ("sensible_j", e["sensible_stored"]),
            ("latent_j", e["latent_stored"]),
            ("convective_j", e["convective_out"]),
            ("imbalance_j", e["imbalance"]),
        ):
            rec[k].append(float(v))
        for eff, er in rep.effects.items():
            effect_wall[eff].append(er.wall_s)
        p_above.append(p[p > p0])
        if not all(np.all(np.isfinite(a)) for a in sim.state.arrays.values() if a.dtype != bool):
            raise SystemExit(f"{name}: non-finite field at step {rep.step}")
        print(
            f"{name} step {rep.step} t={rep.time_s:.2f}s wall={rep.wall_s:.2f}s "
            f"T={rep.max_temperature_k:.1f} p={rep.max_pressure_pa:.3g} "
            f"W={rep.max_strain_energy_j_per_m3:.3g} depth={rep.crater_depth_m * 1e3:.2f}mm",
            flush=True,
        )
        if time.perf_counter() - t0 > wall_limit:
            print(f"{name}: wall limit {wall_limit:.0f} s reached at step {rep.step}", flush=True)
            break
    ckpt = sim.save_checkpoint(RUNS / f"paper_scenes_{name}.h5")
    j = sim.grid.ny // 2 if name != "moving-electrode" else None
    out = RESULTS / f"paper_scenes_{name}.npz"
    RESULTS.mkdir(parents=True, exist_ok=True)
    pa = np.concatenate(p_above) if p_above else np.zeros(0)
    np.savez_compressed(
        out,
        **{k: np.asarray(v) for k, v in rec.items()},
        **{f"effect_wall_{k}": np.asarray(v) for k, v in effect_wall.items()},
        p_above_pa=pa.astype(np.float32),
        temperature_plane=sim.field("temperature")[:, j, :] if j is not None else np.zeros(0),
        level_set_plane=sim.field("level_set")[:, j, :] if j is not None else np.zeros(0),
        meta=json.dumps(
            {
                "scene": name,
                "grid": list(grid),
                "steps_asked": steps,
                "steps_run": sim.step_index,
                "wall_s": time.perf_counter() - t0,
                "checkpoint": str(ckpt.relative_to(ROOT)),
                "block_m": list(scene.block_m),
                "electrode_xy_m": list(scene.electrodes[0].position_m),
                "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                "calls": dict(sim.calls),
            }
        ),
    )
    return out


def _load(name: str) -> dict | None:
    path = RESULTS / f"paper_scenes_{name}.npz"
    if not path.exists():
        return None
    with np.load(path) as z:
        d = {k: z[k] for k in z.files}
    d["meta"] = json.loads(str(d["meta"]))
    return d


def _crossing_time(t: np.ndarray, T: np.ndarray, level: float) -> float | None:
    """First time T(t) reaches level, linear between steps (T before step 1 is T0 = 310.15 K)."""
    tt = np.concatenate([[0.0], t])
    TT = np.concatenate([[310.15], T])
    k = np.flatnonzero(TT >= level)
    if k.size == 0:
        return None
    k = int(k[0])
    return float(tt[k - 1] + (level - TT[k - 1]) / (TT[k] - TT[k - 1]) * (tt[k] - tt[k - 1]))


def report() -> None:
    """Tables and figures from the saved runs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from diathermy.physics.materials import Tissue

    tissue = Tissue()
    runs = {n: d for n in ("fixed-electrode", "moving-electrode") if (d := _load(n)) is not None}
    lines = ["# The paper's scenes on the default grid", ""]
    lines += [
        "Command: `python benchmarks/paper_scenes.py` (runs both scenes, then this report). "
        "Shared 2-core machine, single-threaded BLAS; per-step records in "
        "`paper_scenes_<scene>.npz`.",
        "",
    ]
    for name, d in runs.items():
        m = d["meta"]
        t = d["time_s"]
        lines += [f"## {name}", ""]
        lines += [
            f"Grid {tuple(m['grid'])} nodes, {m['steps_run']} of {m['steps_asked']} steps "
            f"({t[-1]:.2f} s simulated) in {m['wall_s']:.0f} s wall "
            f"(median {np.median(d['wall_s']):.2f} s/step), peak RSS {m['peak_rss_mb']:.0f} MB. "
            f"Solver calls: {m['calls']}.",
            "",
        ]
        t100 = _crossing_time(t, d["t_contact_k"], T_100C)
        t100_max = _crossing_time(t, d["t_max_k"], T_100C)
        i_cut = np.flatnonzero(d["cut_volume_m3"] > 0)
        lines += [
            "| quantity | value |",
            "|---|---|",
            f"| delivered power (median) | {np.median(d['power_w']):.1f} W |",
            f"| time to 100 C at the contact node | "
            f"{'not reached' if t100 is None else f'{t100:.3f} s'} |",
            f"| time to 100 C anywhere (hottest node) | "
            f"{'not reached' if t100_max is None else f'{t100_max:.3f} s'} |",
            f"| peak temperature | {d['t_max_k'].max():.1f} K ({d['t_max_k'].max() - 273.15:.0f} C) |",
            f"| peak pore pressure | {d['p_max_pa'].max() / 1e3:.0f} kPa "
            f"(p_sat of the peak T: {saturation_pressure(d['t_max_k'].max(), tissue) / 1e3:.0f} kPa) |",
            f"| peak strain energy W | {d['w_max_j_per_m3'].max():.3g} J/m^3 "
            f"(kappa = {tissue.damage_kappa_j_per_m3:.3g}) |",
            f"| peak displacement | {d['u_max_m'].max() * 1e3:.3f} mm |",
            f"| first cut | {'none' if i_cut.size == 0 else f'{t[i_cut[0]]:.2f} s'} |",
            f"| final crater depth / volume | {d['crater_depth_m'][-1] * 1e3:.2f} mm / "
            f"{d['cut_volume_m3'][-1] * 1e9:.1f} mm^3 |",
            "",
        ]
        J = d["joule_in_j"][-1]
        lines += [
            "Where the energy went (running totals of the step reports, J):",
            "",
            "| Joule in | sensible stored | latent stored | convective loss | imbalance |",
            "|---|---|---|---|---|",
            f"| {J:.2f} | {d['sensible_j'][-1]:.2f} ({d['sensible_j'][-1] / J:.1%}) | "
            f"{d['latent_j'][-1]:.3f} ({d['latent_j'][-1] / J:.2%}) | "
            f"{d['convective_j'][-1]:.4f} ({d['convective_j'][-1] / J:.3%}) | "
            f"{d['imbalance_j'][-1]:.2e} ({abs(d['imbalance_j'][-1]) / J:.1e} of Joule in) |",
            "",
        ]
        pa = d["p_above_pa"].astype(float)
        if pa.size:
            q = np.percentile(pa, [50, 90, 99])
            lines += [
                "Pore pressure over the run at nodes above p0 (all node-steps):",
                "",
                "| node-steps | min | median | p90 | p99 | max |",
                "|---|---|---|---|---|---|",
                f"| {pa.size} | {pa.min() / 1e3:.1f} kPa | {q[0] / 1e3:.1f} kPa | "
                f"{q[1] / 1e3:.1f} kPa | {q[2] / 1e3:.1f} kPa | {pa.max() / 1e3:.1f} kPa |",
                "",
            ]
        else:
            lines += ["No node rose above p0.", ""]
        n = len(t)
        idx = sorted({min(n - 1, max(0, int(round(s / (t[1] - t[0] if n > 1 else 1)) - 1)))
                      for s in np.linspace(0, t[-1], 9)[1:]} | {n - 1})  # fmt: skip
        lines += [
            "Crater against time:",
            "",
            "| t (s) | T max (K) | p max (kPa) | W max (J/m^3) | depth (mm) | volume (mm^3) |",
            "|---|---|---|---|---|---|",
        ]
        for i in idx:
            lines.append(
                f"| {t[i]:.2f} | {d['t_max_k'][i]:.1f} | {d['p_max_pa'][i] / 1e3:.0f} | "
                f"{d['w_max_j_per_m3'][i]:.3g} | {d['crater_depth_m'][i] * 1e3:.2f} | "
                f"{d['cut_volume_m3'][i] * 1e9:.2f} |"
            )
        lines.append("")
    if runs:
        all_p = np.concatenate([d["p_above_pa"].astype(float) for d in runs.values()])
        if all_p.size:
            lines += [
                "## Pressure range for the dataset generator",
                "",
                f"Both scenes together, nodes above p0: {all_p.min() / 1e3:.1f} to "
                f"{all_p.max() / 1e3:.1f} kPa (p99 {np.percentile(all_p, 99) / 1e3:.1f} kPa). "
                "The generator's default [p_min, p_max] must cover this range.",
                "",
            ]
    _figures(runs, plt)
    (RESULTS / "paper_scenes.md").write_text("\n".join(lines))
    print("\n".join(lines))


def _figures(runs: dict, plt) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for name, d in runs.items():
        axes[0].plot(d["time_s"], d["crater_depth_m"] * 1e3, label=name)
        axes[1].plot(d["time_s"], d["cut_volume_m3"] * 1e9, label=name)
    axes[0].set(xlabel="t (s)", ylabel="crater depth (mm)")
    axes[1].set(xlabel="t (s)", ylabel="cut volume (mm$^3$)")
    axes[0].legend()
    fig.tight_layout()
    fig.savefig(RESULTS / "crater_vs_time.png", dpi=120)
    plt.close(fig)
    d = runs.get("fixed-electrode")
    if d is None or d["temperature_plane"].size == 0:
        return
    m = d["meta"]
    T, phi = d["temperature_plane"], d["level_set_plane"]
    lx, ly, lz = m["block_m"]
    nz, nx = T.shape
    x = np.linspace(0, lx, nx) * 1e3
    z = np.linspace(0, lz, nz) * 1e3
    xe = m["electrode_xy_m"][0] * 1e3
    fig, ax = plt.subplots(figsize=(7, 4))
    im = ax.pcolormesh(x, z, T - 273.15, shading="gouraud", cmap="inferno")
    fig.colorbar(im, ax=ax, label="T (C)")
    ax.contour(x, z, phi, levels=[0.0], colors="cyan", linewidths=1.5)
    ax.contourf(x, z, phi, levels=[phi.min() - 1, 0.0], colors="none", hatches=["//"])
    ax.contour(x, z, T, levels=[T_100C], colors="white", linewidths=0.8, linestyles="--")
    ax.set(
        xlim=(xe - 25, xe + 25),
        ylim=(lz * 1e3 - 30, lz * 1e3),
        xlabel="x (mm)",
        ylabel="z (mm)",
        title=f"fixed electrode, y = {ly / 2 * 1e3:.0f} mm plane, t = {d['time_s'][-1]:.2f} s: "
        "T, cut (cyan, hatched), 100 C (dashed)",
    )
    ax.title.set_fontsize(8)
    ax.set_aspect("equal")
    fig.tight_layout()
    fig.savefig(RESULTS / "crater.png", dpi=120)
    plt.close(fig)


def main() -> None:
    from diathermy.runtime import configure_threads

    configure_threads()  # as the CLI and the server run: one BLAS thread
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("command", nargs="?", default="all", choices=["all", "run", "report"])
    ap.add_argument("--scene", default="fixed-electrode")
    ap.add_argument("--grid", type=int, nargs=3, default=(33, 33, 65), metavar=("NZ", "NY", "NX"))
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--wall-limit", type=float, default=600.0, help="s per scene")
    a = ap.parse_args()
    if a.command == "run":
        run_scene(a.scene, tuple(a.grid), a.steps, a.wall_limit)
    elif a.command == "report":
        report()
    else:
        for name in ("fixed-electrode", "moving-electrode"):
            run_scene(name, tuple(a.grid), a.steps, a.wall_limit)
        report()


if __name__ == "__main__":
    main()
