"""Cost per step of each effect of the default scene, effect set by effect set (one command).

    python benchmarks/effects.py [--grid NZ NY NX] [--steps N] [--checkpoint PATH]
        [--compare OLD_SERVER_DIR [--rounds N]]

Five effect sets, each a superset of the last: electric; + thermal; + vaporization;
+ mechanics; + dissection. Every set starts from the same state, taken in the regime where
every effect works (boiling, pressure, strain energy above kappa, a growing cut): the
checkpoint ``benchmarks/paper_scenes.py`` leaves in ``runs/`` when it exists, else a warm-up
run of the scene until the cut moves (saved to that path, so later runs start from it). Each
set then runs ``--steps`` steps; the per-effect wall times of the step reports give medians
per effect and each effect's share of the step. ``--compare DIR`` also measures the same sets
with another source tree's ``server/`` directory (e.g. the main checkout, before a change),
from the same checkpoint: ``--rounds`` times each, alternating (other tree first, each in its
own process), and reports the fastest round of each tree per set (the least disturbed by other
load on a shared machine) and their ratio.
Writes ``benchmarks/results/effects.md`` and ``effects.png`` (stacked bars).
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
# BENCH_SERVER: the source tree to measure (set by --compare for the other tree's subprocess)
sys.path.insert(0, os.environ.get("BENCH_SERVER", str(ROOT / "server")))

from diathermy.engine.simulation import Simulation  # noqa: E402
from diathermy.runtime import configure_threads  # noqa: E402
from diathermy.scene import builtin_scene  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
SETS = [
    ["electric"],
    ["electric", "thermal"],
    ["electric", "thermal", "vaporization"],
    ["electric", "thermal", "vaporization", "mechanics"],
    ["electric", "thermal", "vaporization", "mechanics", "dissection"],
]
LABELS = ["electric", "+ thermal", "+ vaporization", "+ mechanics", "+ dissection"]


def start_state(grid: tuple[int, int, int], checkpoint: Path) -> tuple[Simulation, str]:
    """A simulation of the default scene in the cutting regime, and where it came from."""
    if checkpoint.exists():
        sim = Simulation.load_checkpoint(checkpoint)
        if sim.scene.resolution is None and tuple(sim.scene.grid) == grid:
            return sim, f"checkpoint {checkpoint.name} (t = {sim.time_s:.2f} s)"
    sim = Simulation(builtin_scene("default").on_uniform_grid(grid))
    t0 = time.perf_counter()
    while sim.step_index < 2000:
        rep = sim.step()
        if rep.ran("dissection") and sim.state["removed"].any() and sim.step_index % 10 == 0:
            break
    sim.save_checkpoint(checkpoint)
    wall = time.perf_counter() - t0
    return sim, f"warm-up of {sim.step_index} steps ({wall:.0f} s wall), saved to {checkpoint.name}"


def with_effects(base: Simulation, effects: list[str]) -> Simulation:
    """A simulation of ``effects`` starting from ``base``'s state."""
    scene = base.scene.model_copy(update={"effects": effects})
    sim = Simulation(scene)
    sim.state = copy.deepcopy(base.state)
    sim.restore_solver_state({}, steps_since_reinit=0, mechanics_current=False)
    return sim


def measure(grid: tuple[int, int, int], steps: int, checkpoint: Path) -> dict[str, Any]:
    """Median step and per-effect wall times (s) of every effect set, and the end state."""
    base, origin = start_state(grid, checkpoint)
    rows = []
    for effects, label in zip(SETS, LABELS, strict=True):
        sim = with_effects(base, effects)
        reports = sim.run(steps)
        per = {e: float(np.median([r.effects[e].wall_s for r in reports])) for e in sim.effects}
        ran = {e: sum(r.effects[e].ran for r in reports) for e in sim.effects}
        step = float(np.median([r.wall_s for r in reports]))
        rep = reports[-1]
        rows.append({"label": label, "step": step, "per": per, "ran": ran, "end": rep.to_dict()})
        print(label, f"{step:.3f} s/step", {k: round(v, 4) for k, v in per.items()}, ran)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {"origin": origin, "rows": rows, "rss_mb": rss}


def measure_tree(server: Path, grid: tuple[int, int, int], steps: int, ckpt: Path) -> dict:
    """``measure`` with the source tree ``server``, in a subprocess."""
    out = RESULTS / "_effects_other.json"
    args = [sys.executable, __file__, "--grid", *map(str, grid), "--steps", str(steps)]
    args += ["--checkpoint", str(ckpt), "--json", str(out)]
    subprocess.run(args, env={**os.environ, "BENCH_SERVER": str(server)}, check=True)
    data = json.loads(out.read_text())
    out.unlink()
    return data


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--grid", type=int, nargs=3, default=(33, 33, 65), metavar=("NZ", "NY", "NX"))
    ap.add_argument("--steps", type=int, default=8)
    ap.add_argument(
        "--checkpoint", type=Path, default=ROOT / "runs" / "paper_scenes_fixed-electrode.h5"
    )
    ap.add_argument("--compare", type=Path, help="another tree's server/ dir to measure too")
    ap.add_argument("--rounds", type=int, default=3, help="alternating rounds with --compare")
    ap.add_argument("--json", type=Path, help=argparse.SUPPRESS)  # --compare's subprocess
    a = ap.parse_args()
    configure_threads()
    grid = tuple(a.grid)
    if a.json is not None:
        a.json.write_text(json.dumps(measure(grid, a.steps, a.checkpoint)))
        return
    if a.compare is None:
        write_results(measure(grid, a.steps, a.checkpoint), None, a, grid)
        return
    if not a.checkpoint.exists():
        start_state(grid, a.checkpoint)  # both trees start from the same saved state
    this = Path(os.environ.get("BENCH_SERVER", str(ROOT / "server")))
    before, after = [], []
    for _ in range(a.rounds):
        before.append(measure_tree(a.compare, grid, a.steps, a.checkpoint))
        after.append(measure_tree(this, grid, a.steps, a.checkpoint))
    write_results(fastest(after), fastest(before), a, grid)


def fastest(runs: list[dict]) -> dict:
    """Per effect set, the round with the smallest median step time (its per-effect times too);
    ``rounds`` keeps every round's step times."""
    out = dict(runs[0])
    out["rows"] = [
        min((run["rows"][i] for run in runs), key=lambda r: r["step"])
        for i in range(len(runs[0]["rows"]))
    ]
    out["rounds"] = [[r["step"] for r in run["rows"]] for run in runs]
    out["rss_mb"] = max(run["rss_mb"] for run in runs)
    return out


def write_results(res: dict, other: dict | None, a: argparse.Namespace, grid: tuple) -> None:
    rows, effects = res["rows"], SETS[-1]
    cmd = f"python benchmarks/effects.py --grid {' '.join(map(str, grid))} --steps {a.steps}"
    if other is not None:
        cmd += f" --compare {a.compare} --rounds {a.rounds}"
    lines = [
        "# Cost per step by effect (default scene)",
        "",
        f"`{cmd}`: grid {grid} nodes, start state: {res['origin']}. Medians over {a.steps} "
        "steps per effect set, from the step reports' per-effect wall times; `ran` counts the "
        "steps in which the effect did work (the rest were skipped with a reason, e.g. the fixed "
        "electrode's potential reused). Shared 2-core machine, single-threaded BLAS; peak RSS "
        f"{res['rss_mb']:.0f} MB.",
        "",
        "| effect set | step (s) | "
        + " | ".join(f"{e} (s, ran)" for e in effects)
        + " | ratio to electric only |",
        "|---|---|" + "---|" * len(effects) + "---|",
    ]
    for r in rows:
        per, ran = r["per"], r["ran"]
        cells = [f"{per[e]:.4f} ({ran[e]}/{a.steps})" if e in per else "—" for e in effects]
        lines.append(
            f"| {r['label']} | {r['step']:.4f} | "
            + " | ".join(cells)
            + f" | {r['step'] / rows[0]['step']:.1f} |"
        )
    last = rows[-1]
    per, rep = last["per"], last["end"]
    total = sum(per.values())
    lines += [
        "",
        "Share of each effect in the full step: "
        + ", ".join(f"{e} {per[e] / total:.0%}" for e in effects)
        + f". State at the end: T max {rep['max_temperature_k']:.0f} K, p max "
        f"{rep['max_pressure_pa'] / 1e3:.0f} kPa, W max "
        f"{rep['max_strain_energy_j_per_m3']:.3g} J/m^3, crater {rep['crater_depth_m'] * 1e3:.2f} mm.",
    ]
    if other is not None:
        lines += [
            "",
            f"## Side by side: before = `{a.compare}`, after = this tree",
            "",
            f"Same start state; {a.rounds} rounds, alternating (before first), each tree in its "
            "own process. The tables above and below take, per effect set, the round with the "
            "fastest median step of each tree; all rounds' medians are listed after.",
            "",
            "| effect set | step before (s) | step after (s) | after / before |",
            "|---|---|---|---|",
        ]
        for before, after in zip(other["rows"], rows, strict=True):
            ratio = after["step"] / before["step"]
            lines.append(
                f"| {after['label']} | {before['step']:.4f} | {after['step']:.4f} | {ratio:.2f} |"
            )
        lines += ["", "| effect set | before, every round (s) | after, every round (s) |"]
        lines += ["|---|---|---|"]
        for i, label in enumerate(LABELS):
            b = ", ".join(f"{run[i]:.4f}" for run in other["rounds"])
            f = ", ".join(f"{run[i]:.4f}" for run in res["rounds"])
            lines.append(f"| {label} | {b} | {f} |")
    lines += ["", "![effects](effects.png)", ""]
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "effects.md").write_text("\n".join(lines))
    print("\n".join(lines))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    bottom = np.zeros(len(rows))
    for e in effects:
        h = np.array([r["per"].get(e, 0.0) for r in rows])
        ax.bar(LABELS, h, bottom=bottom, label=e)
        bottom += h
    ax.set(ylabel="median wall time per step (s)", title=f"default scene, grid {grid}")
    ax.legend()
    plt.setp(ax.get_xticklabels(), rotation=15)
    fig.tight_layout()
    fig.savefig(RESULTS / "effects.png", dpi=120)


if __name__ == "__main__":
    main()
