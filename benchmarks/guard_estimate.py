"""How far the incremental mechanics' energy guard can be trusted: its estimate against the truth.

    python benchmarks/guard_estimate.py [--scenes default fixed-electrode] [--grids own] [--steps N]

The energy guard (``fem.energy_cg``) accepts a step's displacement when its estimate of the
relative energy-norm error, sqrt(r.M r) / ||u||_K with M one V-cycle of the kept AMG hierarchy, is
at most ``mechanics.energy_tolerance``. The estimate is exact only where M = K^-1. Here every
incremental step of the scene (from ``realtime.py``'s checkpoint two steps after the first cut) is
solved again from its own answer to a residual of 1e-12 with the same system, and the true relative
energy-norm error ||u* - u||_K / ||u*||_K of the answer the engine kept is set beside the estimate
the guard read. Writes ``benchmarks/results/guard_estimate.md``: per scene the estimate, the true
error and their ratio, per step and summarised, so the tolerance can be read as the error it
admits.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse.linalg as spla

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from realtime import CACHE, RESULTS, SCENES, load_as, scene_on, warm_up  # noqa: E402

from diathermy.physics.incremental_mechanics import IncrementalFEMBackend  # noqa: E402

TIGHT_RTOL = 1e-12
"""Relative residual of the reference solve (the FEM's own is 1e-6)."""


def true_error(backend: IncrementalFEMBackend, pressure_pa: np.ndarray, u: np.ndarray) -> float:
    """||u* - u||_K / ||u*||_K for the system ``backend`` just solved (its kept operator and
    hierarchy), u* solved from u to ``TIGHT_RTOL`` (on the Jacobi-scaled system, where the energy
    norm is the same)."""
    solver = backend.fem.solver
    assert solver is not None
    A, M, s = solver.krylov.A, solver.krylov.kept_preconditioner, solver.scale
    b = solver.load(pressure_pa, backend.fem.p0_pa) * s
    x = u.ravel() / s
    x_star, info = spla.cg(A, b, x0=x, M=M, rtol=TIGHT_RTOL, atol=0.0, maxiter=5000)
    if info != 0:
        raise RuntimeError(f"the reference solve did not reach {TIGHT_RTOL:g} ({info} iterations)")
    e = x_star - x
    return float(np.sqrt(max(e @ (A @ e), 0.0) / (x_star @ b)))


def record(sim: Any, steps: int) -> list[dict[str, Any]]:
    """``steps`` steps of ``sim`` (incremental) with each mechanics answer's estimate and truth."""
    backend = sim.ctx.mechanics
    if not isinstance(backend, IncrementalFEMBackend):
        raise SystemExit("guard_estimate: the scene's mechanics is not the incremental FEM")
    rows: list[dict[str, Any]] = []
    solve = backend.solve

    def checked(**kw: Any) -> Any:  # the engine's call, then the check on the same system
        out = solve(**kw)
        ex = out.extra
        rows.append(
            {
                "mode": ex.get("mode"),
                "estimate": ex.get("energy_estimate"),
                "tolerance": ex.get("energy_tolerance"),
                "window_estimate": ex.get("window_estimate"),
                "iterations": ex.get("polish_iterations", out.iterations),
                "true": true_error(backend, kw["pressure_pa"], out.u),
            }
        )
        return out

    backend.solve = checked  # type: ignore[method-assign]
    for _ in range(steps):
        rep = sim.step()
        if rows and "step" not in rows[-1]:
            rows[-1]["step"] = rep.step
    return [r for r in rows if "step" in r]


def write(results: dict[str, list[dict[str, Any]]], a: argparse.Namespace, started: str) -> str:
    lines = [
        "# The mechanics energy guard: its estimate against the true error",
        "",
        f"`python benchmarks/guard_estimate.py --scenes {' '.join(a.scenes)} --grids "
        f"{' '.join(a.grids)} --steps {a.steps}` (started {started}, load average "
        f"{os.getloadavg()[0]:.1f}): each scene from `realtime.py`'s checkpoint two steps after "
        "the first cut, incremental mode with the scene's defaults; every mechanics answer the "
        f"engine kept is checked against the same system solved to a residual of {TIGHT_RTOL:g}. "
        "*Estimate*: what the guard read (sqrt(r.M r) / ||u||_K, M a V-cycle of the kept "
        "hierarchy); *true*: ||u* - u||_K / ||u*||_K. Local steps are accepted at estimate <= "
        "the energy tolerance, the interval's solve at <= the interval tolerance.",
        "",
        "| scene | steps | mode | estimate median (max) | true error median (max) | "
        "estimate / true min - median - max |",
        "|---|---|---|---|---|---|",
    ]
    for name, rows in results.items():
        for mode in ("local", "full"):
            sel = [r for r in rows if r["mode"] == mode and r["estimate"] is not None]
            if not sel:
                continue
            est = np.array([r["estimate"] for r in sel])
            true = np.array([r["true"] for r in sel])
            ratio = est / np.maximum(true, 1e-300)
            lines.append(
                f"| {name} | {len(sel)} | {mode} | {np.median(est):.2e} ({est.max():.2e}) | "
                f"{np.median(true):.2e} ({true.max():.2e}) | {ratio.min():.2f} - "
                f"{np.median(ratio):.2f} - {ratio.max():.2f} |"
            )
    lines += ["", "Per step:", ""]
    lines += [
        "| scene | step | mode | polish its | window estimate | estimate | tolerance | true |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, rows in results.items():
        for r in rows:
            w, e, tol = r["window_estimate"], r["estimate"], r["tolerance"]
            lines.append(
                f"| {name} | {r['step']} | {r['mode']} | {r['iterations']} | "
                f"{'-' if w is None else f'{w:.2e}'} | {'-' if e is None else f'{e:.2e}'} | "
                f"{'-' if tol is None else f'{tol:.0e}'} | {r['true']:.2e} |"
            )
    return "\n".join(lines) + "\n"


def main() -> None:
    from diathermy.runtime import configure_threads

    configure_threads()  # as the CLI and the server run: one BLAS thread
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--scenes", nargs="+", choices=SCENES, default=["default", "fixed-electrode"])
    ap.add_argument("--grids", nargs="+", choices=("own", "uniform"), default=["own"])
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--warmup", type=int, default=60, help="steps at most before the cut")
    ap.add_argument("--out", type=Path, default=RESULTS / "guard_estimate.md")
    a = ap.parse_args()
    if a.steps < 1:
        ap.error("--steps must be at least 1")
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    results = {}
    for name in a.scenes:
        for grid in a.grids:
            scene = scene_on(name, grid)
            path, _ = warm_up(scene, CACHE / f"{name}_{grid}.h5", a.warmup)
            results[f"{name}, {grid}"] = record(load_as(path), a.steps)
    text = write(results, a, started)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
