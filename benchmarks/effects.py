"""Cost per step of each effect of the default scene, effect set by effect set (one command).

    python benchmarks/effects.py [--grid NZ NY NX] [--steps N] [--checkpoint PATH]

Five effect sets, each a superset of the last: electric; + thermal; + vaporization;
+ mechanics; + dissection. Every set starts from the same state, taken in the regime where
every effect works (boiling, pressure, strain energy above kappa, a growing cut): the
checkpoint ``benchmarks/paper_scenes.py`` leaves in ``runs/`` when it exists, else a warm-up
run of the scene until the cut moves. Each set then runs ``--steps`` steps; the per-effect wall
times of the step reports give medians per effect and each effect's share of the step.
Writes ``benchmarks/results/effects.md`` and ``effects.png`` (stacked bars).
"""

from __future__ import annotations

import argparse
import copy
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "server"))

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


def start_state(grid: tuple[int, int, int], checkpoint: Path | None) -> tuple[Simulation, str]:
    """A simulation of the default scene in the cutting regime, and where it came from."""
    if checkpoint is not None and checkpoint.exists():
        sim = Simulation.load_checkpoint(checkpoint)
        if tuple(sim.scene.grid) == grid:
            return sim, f"checkpoint {checkpoint.relative_to(ROOT)} (t = {sim.time_s:.2f} s)"
    sim = Simulation(builtin_scene("default").model_copy(update={"grid": grid}))
    t0 = time.perf_counter()
    while sim.step_index < 2000:
        rep = sim.step()
        if rep.ran("dissection") and sim.state["removed"].any() and sim.step_index % 10 == 0:
            break
    return sim, f"warm-up of {sim.step_index} steps ({time.perf_counter() - t0:.0f} s wall)"


def with_effects(base: Simulation, effects: list[str]) -> Simulation:
    """A simulation of ``effects`` starting from ``base``'s state."""
    scene = base.scene.model_copy(update={"effects": effects})
    sim = Simulation(scene)
    sim.state = copy.deepcopy(base.state)
    sim.restore_solver_state({}, steps_since_reinit=0, mechanics_current=False)
    return sim


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--grid", type=int, nargs=3, default=(33, 33, 65), metavar=("NZ", "NY", "NX"))
    ap.add_argument("--steps", type=int, default=8)
    ap.add_argument(
        "--checkpoint", type=Path, default=ROOT / "runs" / "paper_scenes_fixed-electrode.h5"
    )
    a = ap.parse_args()
    configure_threads()
    grid = tuple(a.grid)
    base, origin = start_state(grid, a.checkpoint)
    rows = []
    for effects, label in zip(SETS, LABELS, strict=True):
        sim = with_effects(base, effects)
        reports = sim.run(a.steps)
        per = {e: np.median([r.effects[e].wall_s for r in reports]) for e in sim.effects}
        ran = {e: sum(r.effects[e].ran for r in reports) for e in sim.effects}
        step = float(np.median([r.wall_s for r in reports]))
        rows.append((label, step, per, ran, reports[-1]))
        print(label, f"{step:.3f} s/step", {k: round(v, 4) for k, v in per.items()}, ran)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    effects = SETS[-1]
    lines = [
        "# Cost per step by effect (default scene)",
        "",
        f"`python benchmarks/effects.py --grid {' '.join(map(str, grid))} --steps {a.steps}`: "
        f"grid {grid} nodes, start state: {origin}. Medians over {a.steps} steps per effect set, "
        "from the step reports' per-effect wall times; `ran` counts the steps in which the "
        "effect did work (the rest were skipped with a reason, e.g. the fixed electrode's "
        f"potential reused). Shared 2-core machine, single-threaded BLAS; peak RSS {rss:.0f} MB.",
        "",
        "| effect set | step (s) | "
        + " | ".join(f"{e} (s, ran)" for e in effects)
        + " | ratio to electric only |",
        "|---|---|" + "---|" * len(effects) + "---|",
    ]
    for label, step, per, ran, _ in rows:
        cells = [f"{per[e]:.4f} ({ran[e]}/{a.steps})" if e in per else "—" for e in effects]
        lines.append(
            f"| {label} | {step:.4f} | " + " | ".join(cells) + f" | {step / rows[0][1]:.1f} |"
        )
    label, step, per, _, rep = rows[-1]
    total = sum(per.values())
    lines += [
        "",
        "Share of each effect in the full step: "
        + ", ".join(f"{e} {per[e] / total:.0%}" for e in effects)
        + f". State at the end: T max {rep.max_temperature_k:.0f} K, p max "
        f"{rep.max_pressure_pa / 1e3:.0f} kPa, W max {rep.max_strain_energy_j_per_m3:.3g} J/m^3, "
        f"crater {rep.crater_depth_m * 1e3:.2f} mm.",
        "",
        "![effects](effects.png)",
        "",
    ]
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "effects.md").write_text("\n".join(lines))
    print("\n".join(lines))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    bottom = np.zeros(len(rows))
    for e in effects:
        h = np.array([r[2].get(e, 0.0) for r in rows])
        ax.bar(LABELS, h, bottom=bottom, label=e)
        bottom += h
    ax.set(ylabel="median wall time per step (s)", title=f"default scene, grid {grid}")
    ax.legend()
    plt.setp(ax.get_xticklabels(), rotation=15)
    fig.tight_layout()
    fig.savefig(RESULTS / "effects.png", dpi=120)


if __name__ == "__main__":
    main()
