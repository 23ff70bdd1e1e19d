"""Mechanics predictors where persistence has nothing or the wrong thing (issue #22), and in
steady stepping: error and cost of each predictor, per named case, in one table.

    python benchmarks/predictors.py [--grid 33x33x65] [--power 150] [--model PATH]
                                    [--report-only]

The fixed-electrode scene on a uniform grid (the shipped CNN's 33x33x65 by default) at a high
power (150 W: it boils at step 6 and cuts by step 22, so every case is a short run). A FEM run
that solves in full every step is the reference; on each step of a case every predictor is
applied to exactly that step's system (pressure, topology) and its strain energy compared with
the FEM's (``relative_strain_energy_error``): persistence ('previous': the last displacement,
Ritz-scaled) and the CNN, each alone and with the patch correction, and the engine's 'auto'
choice (with the patch). Named cases:

- ``first-step``: the first mechanics steps of a session (+0: persistence has nothing, u = 0);
- ``cut-event``: the steps right after the first cut changes the topology;
- ``steady``: steady cutting, continued from a checkpoint taken after the cut began;
- ``power-jump``: from that checkpoint, the power jumps x3;
- ``lift-and-place``: the electrode lifted for 3 steps and placed 30 % of the block's width
  away: the first steps in which the new spot boils (persistence knows the old crater only);
- ``restored``: the checkpoint restored without its solver state (fresh operators);
- ``erratic``: a fast, erratic path: each step the electrode jumps to a random spot within
  +-3 % of the block's length (up to 6 mm, 200 mm/s, two cells of 33x33x65).

Writes benchmarks/results/predictors.md and predictors.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
PREDICTORS = ("previous", "previous+patch", "cnn", "cnn+patch", "auto+patch")
CASES = (
    "first-step", "cut-event", "steady", "power-jump", "lift-and-place", "restored", "erratic"
)  # fmt: skip


class Probe:
    """Steps a FEM reference simulation and scores every predictor on the steps asked for."""

    def __init__(self, sim: Any, network: Any | None) -> None:
        self.sim = sim
        self.network = network
        self.graph: Any = None
        self.rows: list[dict[str, Any]] = []

    def step(self, case: str | None, label: str = "") -> dict[str, Any] | None:
        """One step of the reference; scored under ``case`` when given and the mechanics ran."""
        from diathermy.engine.backends import fem_of
        from diathermy.physics.materials import ersatz_youngs_modulus
        from diathermy.physics.patch_correction import node_graph
        from diathermy.physics.predictor_errors import StepSystem, score_start
        from diathermy.physics.predictors import choose_start
        from diathermy.physics.strain_energy import (
            relative_strain_energy_error,
            strain_energy_density,
        )

        sim, t = self.sim, self.sim.tissue
        phi = sim.state["level_set"].copy()
        healthy = ~sim.state["removed"]
        u_prev = sim.state["displacement"].copy()
        rep = sim.step()
        mech = rep.effects["mechanics"]
        if case is None or not mech.ran:
            return None
        fem = fem_of(sim.mechanics)
        solver = fem.solver
        E = ersatz_youngs_modulus(healthy, t.youngs_modulus_pa, t.ersatz_stiffness_ratio)
        if solver.fragments.loose.any():
            E[solver.fragments.loose] = t.ersatz_stiffness_ratio * E.max()
        if self.graph is None:
            self.graph = node_graph(solver.K)
        p, W_ref = sim.state["pressure"], sim.state["strain_energy"]
        system = StepSystem.of(solver, p, t.p_atm_pa, self.graph)
        grads, tets = sim.disc.geom.grads, sim.disc.mesh.tets

        def W(u: np.ndarray) -> np.ndarray:
            return strain_energy_density(grads, tets, u, E, t.poisson_ratio)

        x = mech.extra
        row: dict[str, Any] = {
            "case": case,
            "label": label,
            "step": rep.step,
            "max_pressure_pa": rep.max_pressure_pa,
            "removed_tets": int((~healthy).sum()),
            "topology_changed": bool(x.get("rebuilt", False)),
            "full_s": float(
                x.get("operator_s", 0.0) + x.get("amg_setup_s", 0.0) + x.get("solve_s", 0.0)
            ),  # fmt: skip
            "full_solve_s": float(x.get("amg_setup_s", 0.0) + x.get("solve_s", 0.0)),
            "operator_s": float(x.get("operator_s", 0.0)),
            "full_iterations": mech.iterations,
        }
        net = self.network
        starts: list[tuple[str, Callable[[], np.ndarray]]] = [("previous", lambda: u_prev)]
        if net is not None:
            starts.append(("cnn", lambda: net.predict(p, phi, None)))
        for name, fn in starts:
            for s in score_start(system, name, fn, W, W_ref):
                row[f"{s.name}_error"], row[f"{s.name}_s"] = s.error, s.cost_s
                row[f"{s.name}_residual"], row[f"{s.name}_nodes"] = s.residual, s.patch_nodes
        t0 = time.perf_counter()
        choice = choose_start(
            "auto",
            u_prev=u_prev,
            network=None if net is None else (lambda: net.predict(p, phi, None)),
            network_name="cnn",
            matvec=system.matvec,
            f=system.f,
            free=system.free,
        )
        if choice.start is not None:
            u, res, _ = system.patched(choice.start)
            row["auto+patch_s"] = time.perf_counter() - t0
            row["auto+patch_error"] = relative_strain_energy_error(W(u), W_ref)
            row["auto+patch_residual"] = res
        row["auto_pick"] = choice.start.name if choice.start is not None else "full"
        row["auto_why"] = choice.why
        self.rows.append(row)
        return row


def _reference(scene: Any) -> Any:
    from diathermy.engine.simulation import Simulation

    return Simulation(scene)


def _restore(path: Path, *, with_solver: bool) -> Any:
    """The checkpoint as a simulation: as saved, or without its solver state."""
    from diathermy.engine import checkpoint as persistence
    from diathermy.engine.simulation import Simulation

    if with_solver:
        return Simulation.load_checkpoint(path)
    saved = persistence.read_checkpoint(path)
    sim = Simulation(saved.scene)
    st = sim.state
    st.step, st.time_s, st.arrays = saved.step, saved.time_s, saved.arrays
    st.energy, st.overrides = saved.energy, saved.overrides
    sim.restore_solver_state(
        {}, steps_since_reinit=saved.steps_since_reinit, mechanics_current=saved.mechanics_current
    )
    return sim


def run_cases(
    scene: Any,
    network: Any | None,
    *,
    cut_by: int = 40,
    steady_steps: int = 4,
    place_steps: int = 3,
    place_by: int = 40,
    erratic_steps: int = 5,
    seed: int = 0,
    log: Callable[[str], None] = lambda s: None,
) -> list[dict[str, Any]]:
    """Every case on ``scene`` (full solves every step: the reference), rows per scored step."""
    scene = scene.model_copy(
        update={"solver": scene.solver.model_copy(update={"incremental": False})}
    )
    el = scene.electrodes[0]
    bx, by = scene.block_m[0], scene.block_m[1]
    rows: list[dict[str, Any]] = []
    probe = Probe(_reference(scene), network)
    sim = probe.sim
    # session: the first mechanics steps, then on to the first cut and the steps after it
    first, cut = 0, 0
    for _ in range(cut_by):
        case, label = None, ""
        if 0 < first < 3 or (first == 0 and not sim.state["removed"].any()):
            case, label = "first-step", f"+{first}"
        elif sim.state["removed"].any() and cut < 2:
            case, label = "cut-event", f"+{cut}"
        row = probe.step(case, label)
        if row is not None:
            log(f"{case} {label} step {row['step']}")
            first += case == "first-step"
            cut += case == "cut-event"
        if cut == 2:
            break
    if cut < 2:
        raise RuntimeError(f"no cut within {cut_by} steps: raise the power or cut_by")
    probe.step(None)
    with tempfile.TemporaryDirectory() as tmp:
        ckpt = sim.save_checkpoint(Path(tmp) / "steady.h5")
        for _ in range(steady_steps):
            probe.step("steady")
        rows += probe.rows
        log("steady")
        branch = Probe(_restore(ckpt, with_solver=True), network)
        branch.sim.set_electrode(el.name, power_w=3.0 * el.power_w)
        for i in range(3):
            branch.step("power-jump", f"+{i}")
        rows += branch.rows
        log("power-jump")
        branch = Probe(_restore(ckpt, with_solver=True), network)
        branch.sim.set_electrode(el.name, active=False)
        for _ in range(3):
            branch.step(None)
        x0, y0 = el.position_m
        xn = x0 + 0.3 * by
        branch.sim.set_electrode(el.name, position_m=(xn, y0), active=True)
        pts = branch.sim.disc.mesh.points
        spot = (np.abs(pts[:, 0] - xn) < 0.1 * by) & (np.abs(pts[:, 1] - y0) < 0.1 * by)
        p_atm = branch.sim.tissue.p_atm_pa
        for _ in range(place_by):  # placed: the new spot heats up, then boils
            row = branch.step("lift-and-place", f"+{len(branch.rows)}")
            if row is not None and not np.any(branch.sim.state["pressure"][spot] > p_atm):
                branch.rows.pop()  # not boiling there yet: persistence still has it right
            if len(branch.rows) == place_steps:
                break
        rows += branch.rows
        log("lift-and-place")
        branch = Probe(_restore(ckpt, with_solver=False), network)
        for i in range(2):
            branch.step("restored", f"+{i}")
        rows += branch.rows
        log("restored")
        branch = Probe(_restore(ckpt, with_solver=True), network)
        rng = np.random.default_rng(seed)
        for i in range(erratic_steps):
            dx, dy = rng.uniform(-0.03, 0.03, 2) * bx
            branch.sim.set_electrode(el.name, position_m=(x0 + dx, y0 + dy))
            branch.step("erratic", f"+{i}")
        rows += branch.rows
        log("erratic")
    return rows


def engine_first_steps(
    scene: Any, model: str | None, *, steps: int = 3, max_steps: int = 60
) -> list[dict[str, Any]]:
    """The engine itself (incremental, its default guard) under ``mechanics.predictor``
    'previous' and 'auto': its first ``steps`` mechanics steps, what predicted, local or full,
    the mechanics' wall time and CG iterations, and the simulation's build time."""
    from diathermy.engine.simulation import Simulation

    rows = []
    for predictor in ("previous", "auto"):
        sc = scene.model_copy(
            update={
                "solver": scene.solver.model_copy(update={"incremental": True}),
                "mechanics": scene.mechanics.model_copy(
                    update={"predictor": predictor, "model": model}
                ),
            }
        )
        t0 = time.perf_counter()
        sim = Simulation(sc)
        build_s = time.perf_counter() - t0
        n = 0
        while n < steps and sim.step_index < max_steps:
            rep = sim.step()
            m = rep.effects["mechanics"]
            if not m.ran:
                continue
            rows.append({
                "setting": predictor, "step": rep.step, "build_s": build_s, "mech_s": m.wall_s,
                "iterations": m.iterations, "mode": m.extra["mode"],
                "predictor": m.extra["predictor"], "why": m.extra.get("predictor_why", ""),
            })  # fmt: skip
            n += 1
    return rows


# ---------------------------------------------------------------------- report
def _fmt(v: float) -> str:
    return f"{100 * v:.3g} %" if np.isfinite(v) else "-"


def summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per case: steps, and per predictor max / mean error and median cost; the full solve's."""
    out = []
    for case in CASES:
        r = [x for x in rows if x["case"] == case]
        if not r:
            continue
        s: dict[str, Any] = {
            "case": case,
            "steps": len(r),
            "full_s": statistics.median(x["full_s"] for x in r),
            "operator_s": statistics.median(x["operator_s"] for x in r),
            "full_iterations": statistics.median(x["full_iterations"] for x in r),
            "auto_picks": sorted({x["auto_pick"] for x in r}),
        }
        for k in PREDICTORS:
            if all(f"{k}_error" in x for x in r):
                e = [x[f"{k}_error"] for x in r]
                s[k] = (max(e), statistics.fmean(e), statistics.median(x[f"{k}_s"] for x in r))
        out.append(s)
    return out


def write_report(
    rows: list[dict[str, Any]],
    out_dir: Path,
    meta: dict[str, Any],
    notes: str = "",
    engine: list[dict[str, Any]] | None = None,
) -> None:
    """predictors.md (the tables) and predictors.json (every scored step)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "predictors.json").write_text(
        json.dumps({"meta": meta, "rows": rows, "engine": engine or []}, indent=1)
    )
    heads = " | ".join(f"{k} max / mean, s" for k in PREDICTORS)
    lines = [
        "# Mechanics predictors per situation (issue #22)",
        "",
        f"`{meta['command']}` on {meta['machine']}, grid {meta['grid']}, {meta['power_w']} W, "
        f"model `{meta['model']}`; load average {meta['load']} (2 shared cores: read ratios). "
        f"Whole run {meta['wall_s'] / 60:.1f} min.",
        "",
        "Strain-energy error against the full FEM solve of the same step (max / mean over the "
        "case's scored steps) and the median cost per step in s: prediction + Ritz scale "
        "(+ patch). The full solve's cost is its AMG set-up and CG from the previous "
        "displacement (the reference run's own), plus the operator (re-)assembly, which every "
        "predictor needs as well when the topology changed (column 'operator'). 'auto': the "
        "engine's `mechanics.predictor: auto` choice with the patch (picks: what it took).",
        "",
        f"| case | steps | full solve s (CG its) | operator s | {heads} | auto picks |",
        "|---|---|---|---|" + "---|" * len(PREDICTORS) + "---|",
    ]
    for s in summary(rows):
        cells = []
        for k in PREDICTORS:
            if k in s:
                mx, mean, cost = s[k]
                cells.append(f"{_fmt(mx)} / {_fmt(mean)}, {cost:.3f}")
            else:
                cells.append("-")
        lines.append(
            f"| {s['case']} | {s['steps']} | {s['full_s']:.3f} ({s['full_iterations']:.0f}) | "
            f"{s['operator_s']:.3f} | " + " | ".join(cells) + f" | {', '.join(s['auto_picks'])} |"
        )
    if engine:
        lines += [
            "",
            "In the engine (`solver.incremental`, default guard 1e-2: a start whose patched "
            "residual is above it is solved in full from that start): the first mechanics steps "
            "of a session under `mechanics.predictor` 'previous' and 'auto'.",
            "",
            "| setting | build s | step | predictor | mode | mechanics s | CG its | why |",
            "|---|---|---|---|---|---|---|---|",
        ]
        lines += [
            f"| {e['setting']} | {e['build_s']:.2f} | {e['step']} | {e['predictor']} | "
            f"{e['mode']} | {e['mech_s']:.3f} | {e['iterations']} | {e['why']} |"
            for e in engine
        ]
    lines += [
        "",
        "Per step (error %, cost s):",
        "",
        "| case | step | p max MPa | removed tets | full s | "
        + " | ".join(PREDICTORS)
        + " | auto: why |",
        "|---|---|---|---|---|" + "---|" * len(PREDICTORS) + "---|",
    ]
    for x in rows:
        cells = [
            f"{100 * x[f'{k}_error']:.3g} ({x[f'{k}_s']:.3f})" if f"{k}_error" in x else "-"
            for k in PREDICTORS
        ]
        lines.append(
            f"| {x['case']} {x['label']} | {x['step']} | {x['max_pressure_pa'] / 1e6:.2f} | "
            f"{x['removed_tets']} | {x['full_s']:.3f} | " + " | ".join(cells)
            + f" | {x['auto_why']} |"
        )  # fmt: skip
    if notes:
        lines += ["", notes.rstrip()]
    (out_dir / "predictors.md").write_text("\n".join(lines) + "\n", encoding="utf-8")


def main() -> int:
    a = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    a.add_argument("--grid", default="33x33x65", help="uniform grid NZxNYxNX (33x33x65: the CNN's)")
    a.add_argument("--power", type=float, default=150.0, help="W (high: boils within 6 steps)")
    a.add_argument("--model", help="CNN checkpoint (default: the shipped model of the grid)")
    a.add_argument("--out", type=Path, default=RESULTS)
    a.add_argument("--report-only", action="store_true", help="redo the report from the JSON")
    args = a.parse_args()
    notes_path = args.out / "predictors_notes.md"  # hand-written reading, kept across runs
    notes = notes_path.read_text(encoding="utf-8") if notes_path.is_file() else ""
    if args.report_only:
        data = json.loads((args.out / "predictors.json").read_text())
        write_report(data["rows"], args.out, data["meta"], notes, data.get("engine"))
        return 0
    import torch

    from diathermy.mesh import build_tet_mesh
    from diathermy.runtime import configure_threads
    from diathermy.scene import builtin_scene
    from diathermy.surrogates.backend import default_model_path
    from diathermy.surrogates.predictor import CNNPredictor

    configure_threads()
    torch.set_num_threads(1)
    grid = tuple(int(n) for n in args.grid.split("x"))
    scene = builtin_scene("fixed-electrode").on_uniform_grid(grid)  # type: ignore[arg-type]
    el = scene.electrodes[0].model_copy(update={"power_w": args.power})
    scene = scene.model_copy(update={"electrodes": [el]})
    t0 = time.perf_counter()
    model = args.model or str(default_model_path(scene.grid))
    network = CNNPredictor(build_tet_mesh(scene.node_grid()), model)
    rows = run_cases(scene, network, log=lambda s: print(f"[{time.perf_counter() - t0:.0f} s] {s}"))
    engine = engine_first_steps(scene, model)
    meta = {
        "command": "python benchmarks/predictors.py"
        + (f" --grid {args.grid}" if args.grid != "33x33x65" else ""),
        "machine": platform.machine(),
        "grid": args.grid,
        "power_w": args.power,
        "model": Path(model).name,
        "load": " ".join(f"{v:.1f}" for v in os.getloadavg()),
        "wall_s": time.perf_counter() - t0,
    }
    write_report(rows, args.out, meta, notes, engine)
    print((args.out / "predictors.md").read_text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
