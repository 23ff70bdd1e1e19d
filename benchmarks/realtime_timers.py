"""Where an incremental cutting step's time goes, by wall-clock timers (``realtime.py timers``).

    python benchmarks/realtime.py timers [--scenes default] [--grids own uniform] [--steps 8]

cProfile charges its own overhead to whatever calls most often (it once put 0.2 s a step into
pyamg's ``norm``, which takes ~3 ms timed directly, docs/realtime.md), so this times the named
parts of a step instead: each effect from the step report, and inside the mechanics the parts of
the incremental path (``PROBES``), each a ``perf_counter`` around the function. A part's own
time excludes the parts it calls (the window's first V-cycle, for one, brings the kept
hierarchy's coarse operators up to date: that refresh is its own row), so the rows add up. From
the same checkpoints as ``run`` (two steps after the first cut); one mode, so no lockstep: read
the shares, not seconds across runs. Writes ``realtime_timers.md`` into ``--out``.
"""

from __future__ import annotations

import argparse
import importlib
import os
import time
from collections import Counter, defaultdict
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

PROBES: tuple[tuple[str, str, str], ...] = (
    ("diathermy.physics.mechanics_backend", "FEMBackend.operator_for", "operator update"),
    ("diathermy.fem.galerkin_refresh", "GalerkinRefresh.refresh", "coarse refresh (Galerkin)"),
    ("diathermy.physics.incremental_mechanics", "choose_start", "start (Ritz scale)"),
    ("diathermy.physics.incremental_mechanics", "local_solve", "patch"),
    ("diathermy.physics.polish_window", "WindowedPolish.correct", "window PCG"),
    (
        "diathermy.physics.incremental_mechanics",
        "IncrementalFEMBackend._polish",
        "global check and polish",
    ),
    ("diathermy.physics.mechanics_backend", "FEMBackend.solve", "full solve"),
    ("diathermy.physics.mechanics_backend", "kuhn_strain_energy_density", "strain energy"),
    ("diathermy.physics.mechanics_backend", "strain_energy_density", "strain energy"),
)
"""(module, attribute: a function or ``Class.method``, label) of the mechanics' timed parts,
functions patched where the caller looks them up. ``global check and polish``: PCG with the kept
hierarchy on the whole block (the energy guard's V-cycle and its polish iterations, and every
``mechanics.full_every`` solves the interval's solve); ``full solve``: the FEM solve where
those do not reach their tolerance."""
EFFECTS = ("electric", "thermal", "vaporization", "mechanics", "dissection")


class Timers:
    """Own wall time (s) and calls per label of nested timed calls."""

    def __init__(self) -> None:
        self.own: defaultdict[str, float] = defaultdict(float)
        self.calls: Counter[str] = Counter()
        self._children: list[float] = []  # per open call: the time of its timed callees

    def wrap(self, label: str, f: Callable[..., Any]) -> Callable[..., Any]:
        """``f`` timed under ``label``, its timed callees' time taken out of its own."""

        def timed(*args: Any, **kwargs: Any) -> Any:
            t0 = time.perf_counter()
            self._children.append(0.0)
            try:
                return f(*args, **kwargs)
            finally:
                dt = time.perf_counter() - t0
                self.own[label] += dt - self._children.pop()
                self.calls[label] += 1
                if self._children:
                    self._children[-1] += dt

        return timed

    def clear(self) -> None:
        self.own.clear()
        self.calls.clear()


@contextmanager
def probed(timers: Timers, probes: tuple[tuple[str, str, str], ...] = PROBES) -> Iterator[None]:
    """``probes`` wrapped by ``timers`` while inside; the originals put back after."""
    saved: list[tuple[Any, str, Any]] = []
    try:
        for module, attr, label in probes:
            owner: Any = importlib.import_module(module)
            *path, name = attr.split(".")
            for part in path:
                owner = getattr(owner, part)
            original = owner.__dict__[name] if isinstance(owner, type) else getattr(owner, name)
            saved.append((owner, name, original))
            setattr(owner, name, timers.wrap(label, original))
        yield
    finally:
        for owner, name, original in reversed(saved):
            setattr(owner, name, original)


def step_rows(sim: Any, steps: int, timers: Timers) -> list[dict[str, float]]:
    """``steps`` steps of ``sim``, each a record: the step's wall time, each effect's, and each
    mechanics part's own time (s), with ``calls:`` counts."""
    rows = []
    with probed(timers):
        for _ in range(steps):
            timers.clear()
            t0 = time.perf_counter()
            report = sim.step()
            row: dict[str, float] = {"step": time.perf_counter() - t0}
            for eff in EFFECTS:
                er = report.effects.get(eff)
                row[eff] = er.wall_s if er is not None and er.ran else 0.0
            row.update({f"mechanics: {k}": v for k, v in timers.own.items()})
            row.update({f"calls: {k}": float(v) for k, v in timers.calls.items()})
            rows.append(row)
    return rows


def table(rows: list[dict[str, float]]) -> list[str]:
    """Mean per step (ms), share of the mean step, calls per step, for each effect, each
    mechanics part, the mechanics not in a part and the step outside the effects."""
    n = len(rows)

    def mean(key: str) -> float:
        return sum(r.get(key, 0.0) for r in rows) / n

    step = mean("step")
    parts = sorted({k for r in rows for k in r if k.startswith("mechanics: ")}, key=mean)[::-1]
    lines = [
        f"Median step {np.median([r['step'] for r in rows]) * 1e3:.0f} ms, mean "
        f"{step * 1e3:.0f} ms over {n} steps.",
        "",
        "| part | mean ms per step | share | calls per step |",
        "|---|---:|---:|---:|",
    ]

    def row(label: str, value: float, calls: str = "") -> None:
        value = 0.0 if abs(value) < 5e-5 else value  # a difference's rounding, not a negative
        lines.append(f"| {label} | {value * 1e3:.1f} | {value / step:.0%} | {calls} |")

    for eff in EFFECTS:
        row(eff, mean(eff))
        if eff == "mechanics":
            for p in parts:
                label = p.removeprefix("mechanics: ")
                row(f"- {label}", mean(p), f"{mean('calls: ' + label):.1f}")
            row("- the rest of the mechanics", mean("mechanics") - sum(mean(p) for p in parts))
    row("outside the effects (the step's bookkeeping and report)", step - sum(map(mean, EFFECTS)))
    return lines


def timers(a: argparse.Namespace, started: str, load: Callable[[str, str], Any]) -> Path:
    """The incremental mode's steps per (scene, grid) of ``a`` from ``load(scene, grid)`` (its
    checkpoint continued), timed; the tables into ``a.out / realtime_timers.md``."""
    removal = getattr(a, "removal", "threshold")
    flag = "" if removal == "threshold" else f" --removal {removal}"
    lines = [
        "# Real time: where a cutting step's time goes (incremental mode, wall-clock timers)",
        "",
        f"`python benchmarks/realtime.py timers --scenes {' '.join(a.scenes)} --grids "
        f"{' '.join(a.grids)} --steps {a.steps}{flag}` (started {started}, load average "
        f"{os.getloadavg()[0]:.1f}; one BLAS thread): {a.steps} steps from the checkpoint two "
        "steps after the first cut. Each effect from the step report; inside the mechanics each "
        "part's own time (``realtime_timers.PROBES``: a part's timed callees are their own rows), "
        "so the rows add up to the step.",
        "",
    ]
    for name in a.scenes:
        for grid in a.grids:
            sim = load(name, grid)
            rows = step_rows(sim, a.steps, Timers())
            label = "x".join(map(str, sim.grid.shape))
            kind = "uniform" if sim.grid.is_uniform else "graded"
            lines += [f"## {name}, {label} ({kind}, {sim.grid.n_nodes:,} nodes)", ""]
            lines += table(rows) + [""]
    a.out.mkdir(parents=True, exist_ok=True)
    out = a.out / "realtime_timers.md"
    out.write_text("\n".join(lines), encoding="utf-8")
    print("\n".join(lines))
    return out
