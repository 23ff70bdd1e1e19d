"""Real time (issue #25), ``python benchmarks/realtime.py solvers``: what each solver saving buys.

The fixed-electrode scene (current-density drive, ``benchmarks/convergence.py``'s
``scene_for``) on uniform 33x33x65 and on the graded 0.5 mm grid, from one checkpoint per grid
taken two steps after the first cut (a warm-up run, cached under ``runs/realtime/``). From it
every variant runs ``--steps`` steps, the variants one after another and ``--rounds`` times
over (interleaved, so that other load on a shared machine hits them alike), each a superset of
the last:

- ``main``: the solvers as on main: a new AMG hierarchy whenever the operator changes (the
  mechanics with every cut, the potential with every conductivity change), CG warm-started
  from the previous solution as is;
- ``+ritz``: the mechanics' warm start Ritz-scaled (``KrylovSolver.ritz``; the results' table
  was measured with the potential's Ritz-scaled too, which took 44 CG iterations against 33 on
  the graded grid, so the potential no longer scales its warm start);
- ``+reuse``: hierarchies kept across operator changes, fine level refreshed
  (``KrylovSolver.stale_factor``, the engine's defaults; since 2026-12-06 the mechanics'
  coarse levels follow the cuts as well, ``KrylovSolver.refresh_coarse``, which the committed
  table predates);
- ``+local``: the mechanics prolongation smoother weighted by local row sums instead of a
  spectral-radius estimate (pyamg ``weighting="local"``), a cheaper set-up.

Per variant: the median over steps and rounds of the step's wall time, the mechanics and the
electric effect's wall time, CG iterations and AMG set-ups per step, and each ratio to
``main`` (all in the full mode, ``solver.incremental`` false, so that only the solvers differ).
Writes ``benchmarks/results/realtime_solvers.md``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np
from convergence import scene_for
from realtime import CACHE, RESULTS, load_as, warm_up

from diathermy.engine.backends import fem_of
from diathermy.engine.simulation import Simulation
from diathermy.physics.mechanics import DEFAULT_AMG_OPTIONS

VARIANTS = ("main", "+ritz", "+reuse", "+local")
LOCAL_AMG_OPTIONS: dict[str, Any] = {
    **DEFAULT_AMG_OPTIONS,
    "smooth": ("jacobi", {"omega": 4.0 / 3.0, "weighting": "local"}),
}


def grid_label(fine_mm: float) -> str:
    return "uniform 33x33x65" if fine_mm <= 0 else f"graded {fine_mm:g} mm"


def checkpoint(fine_mm: float) -> Path:
    """The fixed electrode (current-density drive) at ``fine_mm`` two steps after the first cut."""
    path = CACHE / f"fixed_{'uniform' if fine_mm <= 0 else f'{fine_mm:g}mm'}.h5"
    return warm_up(scene_for(fine_mm, moving=False), path, warmup=10_000)[0]


def configure(sim: Simulation, variant: str) -> None:
    """Turn the savings after ``variant`` off on a freshly loaded simulation."""
    level = VARIANTS.index(variant)
    backend = fem_of(sim.ctx.mechanics)
    assert backend is not None
    krylovs = [sim.ctx.potential.solver.krylov, backend.krylov]
    for k in krylovs:
        k.ritz = level >= 1 and k is backend.krylov
        if level < 2:
            k.stale_factor = 0.0
            k.reuse = type(k.reuse)(rebuild_due=True)
    backend.krylov.amg_options = dict(LOCAL_AMG_OPTIONS if level >= 3 else DEFAULT_AMG_OPTIONS)
    if level >= 3:
        backend.krylov.reuse = type(backend.krylov.reuse)(rebuild_due=True)  # set up anew


def run_variant(path: Path, variant: str, steps: int) -> list[dict[str, float]]:
    sim = load_as(path, incremental=False)
    configure(sim, variant)
    rows = []
    for _ in range(steps):
        r = sim.step()
        mech, elec = r.effects["mechanics"], r.effects["electric"]
        rows.append(
            {
                "step_s": r.wall_s,
                "mech_s": mech.wall_s,
                "mech_its": mech.iterations,
                "mech_setups": float(mech.extra.get("amg_setup_s", 0.0) > 0),
                "elec_s": elec.wall_s,
                "elec_its": elec.iterations,
                "elec_setups": float(elec.extra.get("setup_s", 0.0) > 0),
            }
        )
    return rows


def solvers(a: argparse.Namespace, started: str) -> None:
    """Every variant on every grid of ``a`` (``--rounds`` times, interleaved), then the table."""
    results: dict[float, dict[str, list[dict[str, float]]]] = {}
    for fine in a.grids:
        path = checkpoint(fine)
        results[fine] = {v: [] for v in VARIANTS}
        for rnd in range(a.rounds):
            for v in VARIANTS:
                t0 = time.perf_counter()
                results[fine][v] += run_variant(path, v, a.steps)
                print(
                    f"{grid_label(fine)} round {rnd} {v}: {time.perf_counter() - t0:.1f} s",
                    flush=True,
                )
    write(results, a, started)


def write(results: dict, a: argparse.Namespace, started: str) -> None:
    lines = [
        "# Real time: solver savings per cutting step",
        "",
        f"`python benchmarks/realtime.py solvers --steps {a.steps} --rounds {a.rounds}` "
        f"(started {started}); the fixed-electrode scene (current-density drive) from a "
        "checkpoint two steps after the first cut, each variant a superset of the one above "
        "(see the script's docstring). Medians over "
        f"{a.steps} steps x {a.rounds} round(s) on a shared 2-core machine (other sessions' "
        "jobs ran beside it): read the ratios. Iterations and set-ups are per step.",
        "",
    ]
    for fine, by_variant in results.items():
        base = {
            k: float(np.median([r[k] for r in by_variant["main"]]))
            for k in ("step_s", "mech_s", "elec_s")
        }
        lines += [
            f"## {grid_label(fine)}",
            "",
            "| variant | step s | x main | mechanics s | x main | CG its | AMG set-ups | electric s | x main | CG its | AMG set-ups |",
            "|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for v, rows in by_variant.items():
            med = {k: float(np.median([r[k] for r in rows])) for k in rows[0]}
            mean = {k: float(np.mean([r[k] for r in rows])) for k in rows[0]}
            lines.append(
                f"| {v} | {med['step_s']:.2f} | {med['step_s'] / base['step_s']:.2f} | "
                f"{med['mech_s']:.2f} | {med['mech_s'] / base['mech_s']:.2f} | "
                f"{med['mech_its']:.0f} | {mean['mech_setups']:.2f} | {med['elec_s']:.3f} | "
                f"{med['elec_s'] / base['elec_s']:.2f} | {med['elec_its']:.0f} | "
                f"{mean['elec_setups']:.2f} |"
            )
        lines.append("")
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "realtime_solvers.md").write_text("\n".join(lines))
    print("\n".join(lines))
