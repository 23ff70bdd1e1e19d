"""Hybrid-PGD against FEM on the fixed- and moving-electrode scenes (held out from training).

    python benchmarks/pgd.py [--grid 33x33x65] [--steps 400] [--modes 5,15,30] [--model FILE]
        [--scenes fixed-electrode,moving-electrode-slow]
        [--policies residual@0.3,energy5@0.1,energy10@0.1] [--target 0.1]

1. Builds (or reuses, ``--model``) a PGD model on a generic training manifold: the electrode on a
   5 x 3 grid of the top surface, three bump radii, three topologies (intact, two hemispherical
   craters at the block's centre). No state of the benchmark scenes enters it.
2. Runs each scene with the FEM mechanics. At every mechanics solve the *same inputs* (pressure,
   level set, topology, electrode position) also go to the PGD, truncated to 5/15/30 modes, so
   the measured error is the surrogate's alone (no feedback of PGD errors into the cut):
   relative strain-energy error (the paper's metric) against the FEM displacement, and wall time.
3. Enrichment indicators of the largest model's answer, beside its true error (how well each
   tracks it: misses = states above ``--target`` the indicator passes): the equilibrium
   residual, and the estimated strain-energy error after 5 / 10 / 20 Jacobi-CG iterations.
4. One copy of the 15-mode model per enrichment policy, enriched online along the same
   trajectory: above the policy's tolerance one FEM solve adds a mode; the error of what each
   copy returns, the number of modes, the cost per mode and per indicator are reported.

Writes ``benchmarks/results/pgd.md`` and ``pgd.png``. Times are medians over the run; ratios are
PGD / FEM in the same process.
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from dataclasses import dataclass
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
    INDICATOR_ITERATIONS,
    EnrichCriterion,
    enrich,
    enrichment_indicator,
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


@dataclass(frozen=True)
class Policy:
    """An online-enrichment policy: criterion, tolerance on its indicator, CG iterations."""

    criterion: EnrichCriterion
    tol: float
    iterations: int = INDICATOR_ITERATIONS

    @property
    def label(self) -> str:
        if self.criterion == "residual":
            return f"residual > {self.tol:g}"
        return f"energy({self.iterations} CG) > {self.tol:g}"

    @classmethod
    def parse(cls, text: str) -> Policy:
        """``residual@0.3`` or ``energy10@0.1`` (criterion, CG iterations, tolerance)."""
        name, tol = text.split("@")
        if name == "residual":
            return cls("residual", float(tol))
        if not name.startswith("energy"):
            raise SystemExit(f"unknown policy {text!r}: residual@TOL or energyK@TOL")
        return cls("energy", float(tol), int(name[6:] or INDICATOR_ITERATIONS))


class Recorder:
    """FEM mechanics that also feeds each solve's inputs to the PGD variants and records both.

    Per solve: the error of the offline model truncated to each of ``modes``; every indicator
    (the residual and the energy indicator after each of ``indicator_iters`` CG iterations) of
    the largest offline model's answer, beside its true error (tracking, no feedback); and one
    enriched copy of the ``enrich_modes`` model per policy, with the error of what it returns.
    """

    name = "fem"

    def __init__(
        self,
        sim_ref: list[Simulation],
        fem: FEMBackend,
        model: PGDModel,
        modes: list[int],
        policies: list[Policy],
        enrich_modes: int,
        indicator_iters: list[int],
    ) -> None:
        self.sim_ref = sim_ref
        self.fem = fem
        self.model = model
        self.modes = modes
        self.policies = policies
        self.copies = [model.truncated(enrich_modes) for _ in policies]
        self.indicator_iters = indicator_iters
        self.rows: list[dict[str, float]] = []
        self.enrich_s: list[list[float]] = [[] for _ in policies]

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
        t_in = t0 = time.perf_counter()
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

        def err(u: np.ndarray) -> float:
            return relative_strain_energy_error(
                strain_energy_density(grads, tets, u, E_eff, nu), W_ref
            )

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
            row[f"err{k}"] = err(u)
        solver = self.fem.solver
        p0 = tis.p_atm_pa
        # tracking: every indicator of the largest offline model's answer
        u = evaluate(self.model, st, max(self.modes))
        ind = enrichment_indicator("residual", solver, u, pressure_pa, p0)
        row["track_residual"], row["track_residual_s"] = ind.value, ind.seconds
        for k in self.indicator_iters:
            ind = enrichment_indicator("energy", solver, u, pressure_pa, p0, k)
            row[f"track_energy{k}"], row[f"track_energy{k}_s"] = ind.value, ind.seconds
            row[f"track_cg{k}_err"] = err(ind.u)  # the CG-continued answer's own error
        # enrichment: one copy per policy, each along the same FEM trajectory
        for i, pol in enumerate(self.policies):
            t0 = time.perf_counter()
            u = evaluate(self.copies[i], st, None)
            row[f"p{i}_eval_s"] = time.perf_counter() - t0
            row[f"p{i}_before"] = err(u)
            ind = enrichment_indicator(pol.criterion, solver, u, pressure_pa, p0, pol.iterations)
            row[f"p{i}_ind"], row[f"p{i}_ind_s"] = ind.value, ind.seconds
            row[f"p{i}_enriched"] = 0.0
            if ind.value > pol.tol:
                step = enrich(self.copies[i], solver, st, u, pressure_pa, x0=ind.u)
                self.copies[i] = step.model
                self.enrich_s[i].append(step.solve_s)
                u = step.u
                row[f"p{i}_enriched"] = 1.0
                row[f"p{i}_enrich_s"] = step.solve_s
            row[f"p{i}_err"] = err(u)
        row["bookkeeping_s"] = time.perf_counter() - t_in - fem_s
        self.rows.append(row)
        return out


def run_scene(
    name: str,
    grid,
    steps: int,
    model: PGDModel,
    modes: list[int],
    policies: list[Policy],
    enrich_modes: int,
    indicator_iters: list[int],
) -> tuple[Recorder, list[float], float]:
    data = builtin_scene(name).model_dump()
    data["grid"], data["resolution"], data["steps"] = grid, None, steps
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
    rec = Recorder(ref, fem, model, modes, policies, enrich_modes, indicator_iters)
    sim.mechanics = rec  # the recorder is the FEM backend plus bookkeeping
    ref.append(sim)
    step_s = []
    t0 = time.perf_counter()
    for i in range(steps):
        rep = sim.step()
        mech = rep.effects.get("mechanics")
        if mech is not None and mech.ran:
            # the FEM step's own cost: its wall time less the benchmark's bookkeeping
            step_s.append(rep.wall_s - rec.rows[-1]["bookkeeping_s"])
        if (i + 1) % 10 == 0:
            print(
                f"  {name} step {i + 1}/{steps}  {time.perf_counter() - t0:.0f} s  mech solves {len(rec.rows)}",
                flush=True,
            )
    return rec, step_s, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", default="33x33x65")
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--modes", default="5,15,30")
    ap.add_argument(
        "--policies",
        default="residual@0.3,energy5@0.1,energy10@0.1",
        help="online-enrichment policies, each on its own copy: residual@TOL, energyK@TOL",
    )
    ap.add_argument("--target", type=float, default=0.1, help="strain-energy error target (misses)")
    ap.add_argument("--indicator-iters", default="5,10,20", help="CG iterations tracked")
    ap.add_argument("--enrich-modes", type=int, default=15)
    ap.add_argument("--model", default=None, help="reuse this model file (built if missing)")
    ap.add_argument("--scenes", default="fixed-electrode,moving-electrode-slow")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    ap.add_argument("--reuse", default="", help="scenes whose rows come from the last raw dump")
    args = ap.parse_args()
    configure_threads()
    grid = tuple(int(v) for v in args.grid.split("x"))
    modes = [int(v) for v in args.modes.split(",")]
    policies = [Policy.parse(v) for v in args.policies.split(",")]
    indicator_iters = [int(v) for v in args.indicator_iters.split(",")]
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
            name, grid, args.steps, model, modes, policies, args.enrich_modes, indicator_iters
        )
        dump = {
            n: {"rows": r.rows, "step_s": st, "wall": w, "enrich_s": r.enrich_s}
            for n, (r, st, w) in results.items()
        }
        raw.write_text(json.dumps(dump), encoding="utf-8")  # survives a failing report
    write_report(
        Path(args.out), args, grid, model, modes, policies, indicator_iters, results, build_s
    )


def _tracking_lines(results, modes: list[int], iters: list[int], target: float) -> list[str]:
    """How each indicator of the largest offline model's answer tracks its true W error."""
    k_max = max(modes)
    lines = [
        f"## Enrichment indicators against the true error ({k_max} offline modes, no enrichment)",
        "",
        f"Each indicator of the {k_max}-mode answer at every mechanics solve, beside its true "
        f"strain-energy error. `misses`: states with true error > {target:g} that the indicator "
        "passes (at its tolerance: the residual's 0.3, the energy indicators' "
        f"{target:g}); `false alarms`: true error <= {target:g} but indicator above; "
        "`ind / true` median ratio; `CG answer`: median true error of the CG-continued answer "
        "the energy indicator computes on the way; `s`: median cost per evaluation (the FEM "
        "operator is shared with the solve; building it on a topology change is not counted).",
        "",
        "| scene | indicator | tol | states > target | misses | false alarms | ind / true | rank corr. | CG answer | s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, (rec, _, _) in results.items():
        rows = rec.rows
        if not rows:
            continue
        true = np.array([r[f"err{k_max}"] for r in rows])
        cands = [("residual", "track_residual", 0.3, None)] + [
            (f"energy, {k} CG", f"track_energy{k}", target, f"track_cg{k}_err") for k in iters
        ]
        for label, key, tol, cg_key in cands:
            ind = np.array([r[key] for r in rows])
            bad = true > target
            miss = int(np.sum(bad & (ind <= tol)))
            false = int(np.sum(~bad & (ind > tol)))
            ratio = np.median(ind / np.maximum(true, 1e-30))
            rho = _rank_corr(ind, true)
            cg = f"{np.median([r[cg_key] for r in rows]):.1%}" if cg_key else "-"
            lines.append(
                f"| {name} | {label} | {tol:g} | {int(bad.sum())}/{len(rows)} | {miss} | {false} | "
                f"{ratio:.2f} | {rho:.2f} | {cg} | {np.median([r[key + '_s'] for r in rows]):.3f} |"
            )
    return lines + [""]


def _rank_corr(a: np.ndarray, b: np.ndarray) -> float:
    """Spearman rank correlation (nan for fewer than 3 points or a constant series)."""
    if len(a) < 3:
        return float("nan")
    ra, rb = np.argsort(np.argsort(a)), np.argsort(np.argsort(b))
    if np.std(ra) == 0 or np.std(rb) == 0:
        return float("nan")
    return float(np.corrcoef(ra, rb)[0, 1])


def _policy_lines(results, policies: list[Policy], enrich_modes: int, target: float) -> list[str]:
    """What each enrichment policy returned, and what it cost."""
    lines = [
        f"## Online enrichment ({enrich_modes} offline modes + online modes, one copy per policy)",
        "",
        f"`misses`: returned answers with true error > {target:g}; `modes added` = FEM solves; "
        "`s per mode`: median FEM solve of one enrichment (warm-started from the indicator's "
        "answer); `indicator s`: median per state; `step ratio`: median whole step with this "
        "policy's mechanics (state reduction + modes + indicator + enrichments) / whole FEM step; "
        "`total ratio`: the same summed over the steps with a mechanics solve (enrichments "
        "included, which the median skips).",
        "",
        "| scene | policy | mech solves | modes added | s per mode | indicator s | FEM solve s | "
        "max error | median error | misses | step ratio | total ratio |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, (rec, step_s, _) in results.items():
        rows = rec.rows
        if not rows:
            continue
        fem_s = np.array([r["fem_s"] for r in rows])
        for i, pol in enumerate(policies):
            e = np.array([r[f"p{i}_err"] for r in rows])
            n_en = int(sum(r[f"p{i}_enriched"] for r in rows))
            cost = np.array(
                [
                    r["reduce_s"]
                    + r[f"p{i}_eval_s"]
                    + r[f"p{i}_ind_s"]
                    + r.get(f"p{i}_enrich_s", 0.0)
                    for r in rows
                ]
            )
            steps = np.array(step_s)
            same = len(step_s) == len(rows)
            ratio = np.median((steps - fem_s + cost) / steps) if same else float("nan")
            total = np.sum(steps - fem_s + cost) / np.sum(steps) if same else float("nan")
            es = rec.enrich_s[i]
            lines.append(
                f"| {name} | {pol.label} | {len(rows)} | {n_en} | "
                f"{(np.median(es) if es else float('nan')):.2f} | "
                f"{np.median([r[f'p{i}_ind_s'] for r in rows]):.3f} | {np.median(fem_s):.2f} | "
                f"{e.max():.1%} | {np.median(e):.1%} | {int(np.sum(e > target))} | {ratio:.3f} | {total:.3f} |"
            )
    return lines + [""]


def write_report(
    out: Path,
    args,
    grid,
    model: PGDModel,
    modes: list[int],
    policies: list[Policy],
    iters: list[int],
    results,
    build_s: float,
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
        f"--scenes {args.scenes} --policies {args.policies} --target {args.target}` on x86_64, "
        "2 shared cores (one used by another worker: treat absolute times as +-30 %; ratios are "
        f"within one process). Peak RSS {peak_mb:.0f} MB.",
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
        "## Strain-energy error of PGD against FEM on the FEM trajectory (paper's Figs. 10, 11, 15)",
        "",
        "Each mechanics solve of the FEM run is also answered by the PGD from the same inputs. "
        "`max`/`median`/`last` over the steps with a mechanics solve; `early`/`late` = mean over "
        "the first/last third of those steps (growth over time); mech ratio = PGD evaluation "
        "(state reduction + modes) / FEM mechanics solve, medians; step ratio = whole step with "
        "PGD mechanics / whole FEM step, medians. Published (paper, its own grid, not measured "
        "here): 13 % max error on the fixed electrode with 15 modes, 69 % on the moving one, "
        "~3 s per online-enriched mode.",
        "",
        "| scene | steps (mech) | modes | max | median | last | early | late | PGD s | FEM s | mech ratio | step ratio |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    fig, axes = plt.subplots(2, len(results), figsize=(6 * len(results), 7.5), squeeze=False)
    for ax, ax2, (name, (rec, step_s, wall)) in zip(axes[0], axes[1], results.items(), strict=True):
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
            ax2.set_axis_off()
            lines.append(
                f"| {name} | {args.steps} (0) | - | no mechanics solve in these steps (wall {wall:.0f} s) | | | | | | | | |"
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
        markers = ["ko", "r^", "mv"]
        for i, pol in enumerate(policies):
            ee = np.array([r[f"p{i}_err"] for r in rows])
            ax2.plot(
                t,
                100 * np.maximum(ee, 1e-4),
                markers[i % len(markers)],
                ms=2.5,
                alpha=0.6,
                label=f"{args.enrich_modes} modes + online, {pol.label}",
            )
        ax2.axhline(100 * args.target, color="grey", lw=0.8)
        ax.set_title(f"{name}: offline PGD")
        ax2.set_title(f"{name}: online (enriched = exact, at 0.01 %)")
        for a in (ax, ax2):
            a.set_xlabel("time (s)")
            a.set_ylabel("strain-energy error (%)")
            a.set_yscale("log")
            a.grid(True, which="both", alpha=0.3)
            a.legend(fontsize=7)
        outside = int(sum(1 - r["inside"] for r in rows))
        lines.append(
            f"|  | topology distance to the training set median {np.median([r['topo_dist'] for r in rows]):.3f}, "
            f"max {max(r['topo_dist'] for r in rows):.3f}; states outside the parameter box: {outside}; "
            f"Q {min(r['Q'] for r in rows):.2e}..{max(r['Q'] for r in rows):.2e} Pa m^3, "
            f"r {1e3 * min(r['r'] for r in rows):.2f}..{1e3 * max(r['r'] for r in rows):.2f} mm; "
            f"first solve t = {t[0]:.2f} s; scene wall {wall:.0f} s | | | | | | | | | | |"
        )
    lines += [
        "",
        *_tracking_lines(results, modes, iters, args.target),
        *_policy_lines(results, policies, args.enrich_modes, args.target),
        "![strain-energy error over time](pgd.png)",
        "",
    ]
    fig.tight_layout()
    fig.savefig(out / "pgd.png", dpi=110)
    (out / "pgd.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
