"""Hybrid-PGD against FEM on the fixed- and moving-electrode scenes (held out from training).

    python benchmarks/pgd.py [--grid 17x17x33] [--steps 400] [--modes 5,15,30] [--enrich-tol 0.3]

1. Builds (or reuses, ``--model``) a PGD model on a generic training manifold: the electrode on a
   5 x 3 grid of the top surface, three bump radii, three topologies (intact, two hemispherical
   craters at the block's centre). No state of the benchmark scenes enters it.
2. Runs each scene with the FEM mechanics. At every mechanics solve the *same inputs* (pressure,
   level set, topology, electrode position) also go to the PGD, truncated to 5/15/30 modes, so
   the measured error is the surrogate's alone (no feedback of PGD errors into the cut):
   relative strain-energy error (the paper's metric) against the FEM displacement, and wall time.
3. A 15-mode copy is enriched online along the same trajectory: whenever the equilibrium residual
   ||f - K u|| / ||f|| of its answer exceeds ``--enrich-tol``, one FEM solve warm-started from
   the PGD answer adds a mode; its error, the number of modes and the cost per mode are reported.

Writes ``benchmarks/results/pgd.md`` and ``pgd.png``. Times are medians over the run; ratios are
PGD / FEM in the same process.
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "server"))

from diathermy.engine.electrodes import electrode_pose  # noqa: E402
from diathermy.engine.simulation import Simulation  # noqa: E402
from diathermy.physics.mechanics_backend import FEMBackend, MechanicsOutput  # noqa: E402
from diathermy.physics.strain_energy import (  # noqa: E402
    relative_strain_energy_error,
    strain_energy_density,
)
from diathermy.runtime import configure_threads  # noqa: E402
from diathermy.scene import builtin_scene, scene_from_dict  # noqa: E402
from diathermy.surrogates.pgd.model import PGDModel, load_model, save_model  # noqa: E402
from diathermy.surrogates.pgd.offline import TrainingManifold, build_model  # noqa: E402
from diathermy.surrogates.pgd.online import (  # noqa: E402
    enrich,
    equilibrium_residual,
    evaluate,
    reduce_state,
)


def manifold_for(
    grid: tuple[int, int, int], block: tuple[float, float, float], modes: int
) -> TrainingManifold:
    """The generic training manifold of the benchmark (see the module docstring)."""
    h = block[0] / (grid[2] - 1)
    return TrainingManifold(
        electrode_x_m=(0.04, 0.07, 0.10, 0.13, 0.16),
        electrode_y_m=(0.03, 0.05, 0.07),
        radius_m=(0.3 * h, 0.6 * h, 1.2 * h),
        craters=((0.1, 0.05, 0.0), (0.1, 0.05, 1.5 * h), (0.1, 0.05, 3.0 * h)),
        n_modes=modes,
        tol=1e-6,
        fem_rtol=1e-6,
    )


class Recorder:
    """FEM mechanics that also feeds each solve's inputs to the PGD variants and records both."""

    name = "fem"

    def __init__(
        self,
        sim_ref: list[Simulation],
        fem: FEMBackend,
        model: PGDModel,
        modes: list[int],
        enrich_tol: float,
        enrich_modes: int,
    ) -> None:
        self.sim_ref = sim_ref
        self.fem = fem
        self.model = model
        self.modes = modes
        self.enrich_tol = enrich_tol
        self.enriched = model.truncated(enrich_modes)
        self.rows: list[dict[str, float]] = []
        self.enrich_s: list[float] = []

    def _position(self) -> tuple[float, float] | None:
        sim = self.sim_ref[0]
        t_mid = sim.state.time_s + 0.5 * sim.scene.dt_s
        for el in sim.scene.electrodes:
            pose = electrode_pose(el, t_mid, sim.state.overrides.get(el.name))
            if pose.active:
                return pose.position_m
        return None

    def solve(
        self, *, pressure_pa, level_set_m, youngs_modulus_pa, healthy, warm_start
    ) -> MechanicsOutput:
        sim = self.sim_ref[0]
        t0 = time.perf_counter()
        out = self.fem.solve(
            pressure_pa=pressure_pa,
            level_set_m=level_set_m,
            youngs_modulus_pa=youngs_modulus_pa,
            healthy=healthy,
            warm_start=warm_start,
        )
        fem_s = time.perf_counter() - t0
        tis = sim.tissue
        E_eff = youngs_modulus_pa.copy()
        if out.loose_tets is not None:
            E_eff[out.loose_tets] = tis.ersatz_stiffness_ratio * tis.youngs_modulus_pa
        grads, tets, nu = sim.disc.geom.grads, sim.disc.mesh.tets, tis.poisson_ratio
        W_ref = strain_energy_density(grads, tets, out.u, E_eff, nu)
        row: dict[str, float] = {"time_s": sim.state.time_s + sim.scene.dt_s, "fem_s": fem_s}
        t0 = time.perf_counter()
        st = reduce_state(
            self.model,
            sim.disc.mesh,
            sim.disc.grid,
            sim.disc.geom.volumes,
            pressure_pa=pressure_pa,
            level_set_m=level_set_m,
            healthy=healthy,
            position_m=self._position(),
        )
        row["reduce_s"] = time.perf_counter() - t0
        row.update(
            inside=float(st.inside),
            topo_dist=st.topology_distance,
            Q=st.strength_pa_m3,
            r=st.radius_m,
        )
        for k in self.modes:
            t0 = time.perf_counter()
            u = evaluate(self.model, st, k)
            row[f"eval{k}_s"] = time.perf_counter() - t0
            row[f"err{k}"] = relative_strain_energy_error(
                strain_energy_density(grads, tets, u, E_eff, nu), W_ref
            )
        solver = self.fem.solver
        p0 = tis.p_atm_pa
        u = evaluate(self.enriched, st, None)
        row["resid"] = equilibrium_residual(solver, u, pressure_pa, p0)
        row["enriched"] = 0.0
        if row["resid"] > self.enrich_tol:
            step = enrich(self.enriched, solver, st, u, pressure_pa)
            self.enriched = step.model
            self.enrich_s.append(step.solve_s)
            u = step.u
            row["enriched"] = 1.0
            row["enrich_s"] = step.solve_s
        row["err_enriched"] = relative_strain_energy_error(
            strain_energy_density(grads, tets, u, E_eff, nu), W_ref
        )
        row["online_modes"] = float(self.enriched.n_online)
        self.rows.append(row)
        return out


MOVING_START_S: list[float | None] = [None]


def run_scene(
    name: str,
    grid,
    steps: int,
    model: PGDModel,
    modes: list[int],
    enrich_tol: float,
    enrich_modes: int,
) -> tuple[Recorder, list[float], float]:
    data = builtin_scene(name).model_dump()
    data["grid"], data["steps"] = grid, steps
    if name == "moving-electrode" and MOVING_START_S[0] is not None:
        data["electrodes"][0]["path"]["start_s"] = MOVING_START_S[0]
    scene = scene_from_dict(data)
    ref: list[Simulation] = []
    tis = scene.material
    sim = Simulation(scene)
    fem = FEMBackend(
        sim.disc.mesh,
        poisson_ratio=tis.poisson_ratio,
        p0_pa=tis.p_atm_pa,
        rtol=scene.mechanics.rtol,
        ersatz_ratio=tis.ersatz_stiffness_ratio,
    )
    rec = Recorder(ref, fem, model, modes, enrich_tol, enrich_modes)
    sim._mechanics = rec  # the recorder is the FEM backend plus bookkeeping
    ref.append(sim)
    step_s = []
    t0 = time.perf_counter()
    for i in range(steps):
        rep = sim.step()
        mech = rep.effects.get("mechanics")
        if mech is not None and mech.ran:
            step_s.append(rep.wall_s)
        if (i + 1) % 10 == 0:
            print(
                f"  {name} step {i + 1}/{steps}  {time.perf_counter() - t0:.0f} s  mech solves {len(rec.rows)}",
                flush=True,
            )
    return rec, step_s, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", default="17x17x33")
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--modes", default="5,15,30")
    ap.add_argument("--enrich-tol", type=float, default=0.3)
    ap.add_argument("--enrich-modes", type=int, default=15)
    ap.add_argument("--model", default=None, help="reuse this model file (built if missing)")
    ap.add_argument("--scenes", default="fixed-electrode,moving-electrode")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    ap.add_argument(
        "--moving-start-s",
        type=float,
        default=4.5,
        help="the moving electrode dwells at its first waypoint until this time (s): on the "
        "17x17x33 grid a 50 W electrode moving from t = 0 never boils the tissue (no mechanics)",
    )
    ap.add_argument("--reuse", default="", help="scenes whose rows come from the last raw dump")
    args = ap.parse_args()
    MOVING_START_S[0] = args.moving_start_s if args.moving_start_s > 0 else None
    configure_threads()
    grid = tuple(int(v) for v in args.grid.split("x"))
    modes = [int(v) for v in args.modes.split(",")]
    block = (0.2, 0.1, 0.1)
    tissue = builtin_scene("fixed-electrode").material
    model_path = Path(args.model) if args.model else Path(f"/tmp/pgd_bench_{args.grid}.npz")
    t0 = time.perf_counter()
    if model_path.exists():
        model = load_model(model_path, grid_shape=grid, block_m=block)
        print(f"reusing {model_path}")
    else:
        model = build_model(
            manifold_for(grid, block, max(modes)), grid, block, tissue, progress=print
        )
        save_model(model, model_path)
    build_s = time.perf_counter() - t0
    results = {}
    raw = Path(f"/tmp/pgd_bench_{args.grid}_raw.json")
    old = json.loads(raw.read_text()) if args.reuse and raw.exists() else {}
    for name in args.scenes.split(","):
        if name in args.reuse.split(",") and name in old:
            o = old[name]
            results[name] = (
                SimpleNamespace(rows=o["rows"], enrich_s=o["enrich_s"]),
                o["step_s"],
                o["wall"],
            )
            print(f"scene {name}: rows reused from {raw}")
            continue
        print(f"scene {name}", flush=True)
        results[name] = run_scene(
            name, grid, args.steps, model, modes, args.enrich_tol, args.enrich_modes
        )
        rec, step_s, wall = results[name]
        dump = {
            n: {"rows": r.rows, "step_s": st, "wall": w, "enrich_s": r.enrich_s}
            for n, (r, st, w) in results.items()
        }
        raw.write_text(json.dumps(dump), encoding="utf-8")  # survives a failing report
    write_report(Path(args.out), args, grid, model, modes, results, build_s)


def write_report(
    out: Path, args, grid, model: PGDModel, modes: list[int], results, build_s: float
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    info = model.build_info
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    hist = model.residual_history
    lines = [
        "# Hybrid-PGD baseline against FEM",
        "",
        f"`python benchmarks/pgd.py --grid {args.grid} --steps {args.steps} --modes {args.modes} "
        f"--enrich-tol {args.enrich_tol}` on x86_64, 2 shared cores (load from other workers: "
        "treat absolute times as +-30 %; ratios are within one process). Peak RSS "
        f"{peak_mb:.0f} MB.",
        "",
        "## Offline build (training manifold, no benchmark state in it)",
        "",
        f"- grid {'x'.join(map(str, grid))}; electrode x {[round(float(v), 3) for v in model.s_x]} m, "
        f"y {[round(float(v), 3) for v in model.s_y]} m; bump radii {[round(float(v) * 1e3, 2) for v in model.radius_m]} mm; "
        f"topologies: {[[round(v, 4) for v in c] for c in info.get('craters', [])]} (x, y, R in m; R = 0 intact)",
        f"- {info.get('snapshots')} FEM snapshots in {info.get('snapshot_s', 0):.0f} s, greedy "
        f"enrichment of {model.n_modes} modes in {info.get('enrichment_s', 0):.1f} s "
        f"(build or load this run: {build_s:.0f} s)",
        "- relative Frobenius residual of the snapshot tensor: "
        + ", ".join(f"{k} modes {hist[k - 1]:.3f}" for k in modes if k <= len(hist)),
        "",
        "## Strain-energy error of PGD against FEM on the FEM trajectory",
        "",
        "Each mechanics solve of the FEM run is also answered by the PGD from the same inputs. "
        "`max`/`median`/`last` over the steps with a mechanics solve; `early`/`late` = mean over "
        "the first/last third of those steps (growth over time); time ratio = PGD evaluation "
        "(state reduction + modes) / FEM mechanics solve, medians; step ratio = whole step with "
        "PGD mechanics / whole FEM step, medians.",
        "",
        "| scene | steps (mech) | modes | max | median | last | early | late | PGD s | FEM s | mech ratio | step ratio |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    fig, axes = plt.subplots(1, len(results), figsize=(6 * len(results), 4), squeeze=False)
    summary_enrich = []
    for ax, (name, (rec, step_s, wall)) in zip(axes[0], results.items(), strict=True):
        rows = rec.rows
        if not rows:
            ax.set_title(name)
            ax.text(
                0.5,
                0.5,
                "no mechanics solve:\nthe tissue never boils in these steps",
                ha="center",
                va="center",
            )
            ax.set_axis_off()
            lines.append(
                f"| {name} | {args.steps} (0) | - | no mechanics solve in these steps | | | | | | | | |"
            )
            continue
        t = np.array([r["time_s"] for r in rows])
        fem_s = np.array([r["fem_s"] for r in rows])
        third = max(1, len(rows) // 3)
        for k in modes:
            e = np.array([r[f"err{k}"] for r in rows])
            pgd_s = np.array([r["reduce_s"] + r[f"eval{k}_s"] for r in rows])
            step_ratio = (
                np.median((np.array(step_s) - fem_s + pgd_s) / np.array(step_s))
                if len(step_s) == len(rows)
                else float("nan")
            )
            lines.append(
                f"| {name} | {args.steps} ({len(rows)}) | {k} | {e.max():.1%} | {np.median(e):.1%} | {e[-1]:.1%} | "
                f"{e[:third].mean():.1%} | {e[-third:].mean():.1%} | {np.median(pgd_s):.4f} | {np.median(fem_s):.2f} | "
                f"{np.median(pgd_s) / np.median(fem_s):.4f} | {step_ratio:.3f} |"
            )
            ax.plot(t, 100 * e, label=f"PGD {k} modes")
        ee = np.array([r["err_enriched"] for r in rows])
        ax.plot(t, 100 * ee, "k--", label=f"{args.enrich_modes} modes + online enrichment")
        ax.set_title(name)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("strain-energy error (%)")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        n_en = int(sum(r["enriched"] for r in rows))
        res = np.array([r["resid"] for r in rows])
        summary_enrich.append(
            f"| {name} | {len(rows)} | {np.median(res):.3f} / {res.max():.3f} | {n_en} | "
            f"{(np.median(rec.enrich_s) if rec.enrich_s else float('nan')):.2f} | {np.median(fem_s):.2f} | "
            f"{ee.max():.1%} | {np.median(ee):.1%} |"
        )
        outside = int(sum(1 - r["inside"] for r in rows))
        summary_enrich.append(
            f"|  | topology distance to the training set median {np.median([r['topo_dist'] for r in rows]):.3f}, "
            f"max {max(r['topo_dist'] for r in rows):.3f}; states outside the parameter box: {outside}; "
            f"Q {min(r['Q'] for r in rows):.2e}..{max(r['Q'] for r in rows):.2e} Pa m^3, "
            f"r {1e3 * min(r['r'] for r in rows):.2f}..{1e3 * max(r['r'] for r in rows):.2f} mm; scene wall {wall:.0f} s | | | | | | |"
        )
    lines += [
        "",
        f"## Online enrichment ({args.enrich_modes} offline modes, tolerance {args.enrich_tol} on ||f - K u|| / ||f||)",
        "",
        "| scene | mech solves | residual median / max (before) | modes added | s per mode | FEM solve s | max error | median error |",
        "|---|---|---|---|---|---|---|---|",
        *summary_enrich,
        "",
        "![strain-energy error over time](pgd.png)",
        "",
    ]
    fig.tight_layout()
    fig.savefig(out / "pgd.png", dpi=110)
    (out / "pgd.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
