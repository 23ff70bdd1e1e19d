"""Real time (issue #25): what a cutting step costs, full against incremental, one command.

    python benchmarks/realtime.py run [--scenes NAME ...] [--grids own uniform] [--steps N] [--tight]
        [--tolerances X ...] [--variant 'section.key=value, ...' ...] [--from-start | --from-step N]
    python benchmarks/realtime.py report FOLDER   # a run's table and plots again from its json
    python benchmarks/realtime.py profile [--scenes default] [--grids own uniform] [--steps N]
    python benchmarks/realtime.py timers [--scenes default] [--grids own uniform] [--steps N]
    python benchmarks/realtime.py solvers [--grids 0 0.5] [--steps N] [--rounds N]  # realtime_solvers.py

``run``: per built-in scene (``default``, ``fixed-electrode``, ``moving-electrode`` at the paper's
12.35 mm/s, ``moving-electrode-slow``, ``coagulation``) and per grid (``own``: the scene's graded
grid; ``uniform``: 33x33x65), a warm-up run with the engine's defaults to two steps after the
first cut (or ``--warmup`` steps where nothing cuts by then) is checkpointed (cached under
``runs/realtime/``); from it every mode steps ``--steps`` steps in lockstep (one step of each in
turn, so that other load on a shared machine hits them alike): ``full`` (``solver.incremental``
false: every effect solved in full every step, the reference), ``incremental`` (the default:
the mechanics from the previous displacement, Ritz-scaled, patch-corrected, a full solve when
the residual check or the interval asks for it) and, on the uniform grid that has a shipped
model, ``cnn`` (the CNN predictor with its patch), and where the scene has mechanics
``persistence`` (the trivial baseline: the last displacement, Ritz-scaled, as the answer); with ``--tight`` also the incremental mode
without its windowed polish (``TIGHT_MODE``: every polish iteration over the whole block), and
with ``--tolerances`` the incremental mode at each of those ``mechanics.energy_tolerance`` values
(what a looser guard buys and costs), with each ``--variant`` the incremental mode with those
``solver`` and ``mechanics`` settings (``solver.incremental=false``: the full mode with them) (e.g. ``'solver.electric_energy_tolerance=1e-4,
mechanics.energy_tolerance=0.01'``). ``--from-start`` steps every mode from the scene's first
step instead (a whole run when ``--steps`` is the scene's: the heating, the first vaporization and
mechanics solve and the cut, where persistence has nothing or little to start from); the table
then also gives each mode's cutting phase (the steps from its first cut on) on its own.
``--from-step N`` steps them from the state after exactly N steps in the scene's own settings
(checkpointed as the warm-up is): a window of a whole run, e.g. around the step where two modes'
cuts part, without paying the full mode for the steps before it. Per mode: median, p90 and mean wall time per step,
the real-time factor (dt / median wall) and the sustained one (dt / mean wall), the median
time of each effect, the mechanics' share of local steps, and against ``full`` at the same step the max and mean strain-energy error and
the max temperature error, and the final cut-volume difference. Writes
``realtime.md``, ``realtime.json`` (every step's record), ``realtime.png`` (wall time per step)
and ``realtime_errors.png`` (each mode's errors per step against the targets) into ``--out``
(default ``benchmarks/results``); ``report FOLDER`` writes them again from the json. With more
than one (scene, grid) pair each pair runs in a process of its own (``run_apart``: memory) and
the results are merged into one table.

``profile``: the same checkpoints, the incremental mode only, under cProfile: the functions
that take the time of a cutting step (``benchmarks/results/realtime_profile.md``).

``timers``: the same, by wall-clock timers around each effect and the mechanics' parts instead
(``realtime_timers.py``: cProfile's overhead misplaces time): ``realtime_timers.md``.

``solvers``: what each solver saving buys in the full mode (``realtime_solvers.py``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "server"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from convergence import UNIFORM  # noqa: E402
from realtime_report import EFFECTS, read_run, write_run  # noqa: E402

from diathermy.engine.simulation import Simulation  # noqa: E402
from diathermy.physics.strain_energy import relative_strain_energy_error  # noqa: E402
from diathermy.scene import Scene, builtin_scene  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
CACHE = ROOT / "runs" / "realtime"
SCENES = ("default", "fixed-electrode", "moving-electrode", "moving-electrode-slow", "coagulation")


def warm_up(scene: Scene, path: Path, warmup: int, exact: bool = False) -> tuple[Path, int | None]:
    """``scene`` stepped to two steps after its first cut, or ``warmup`` steps if it has not cut
    by then (``exact``: ``warmup`` steps, cut or not), checkpointed at ``path`` (reused when it
    exists for the same scene, settings included); (path, first cut step or None)."""
    meta = path.with_suffix(".json")
    scene_json = scene.model_dump_json()
    if path.exists() and meta.exists():
        cached = json.loads(meta.read_text())
        # a checkpoint carries its scene's settings: one warmed up under other defaults would
        # run the 'incremental' mode with those, so it is warmed up again
        if cached.get("scene") == scene_json:
            return path, cached["first_cut_step"]
    path.parent.mkdir(parents=True, exist_ok=True)
    sim = Simulation(scene)
    after_cut: int | None = None
    while (
        sim.step_index < warmup
        if exact
        else (after_cut is None and sim.step_index < warmup)
        or (after_cut is not None and sim.step_index < after_cut + 2)
    ):
        r = sim.step()
        if after_cut is None and r.cut_volume_m3 > 0:
            after_cut = sim.step_index
        print(f"  {scene.name} warm-up step {r.step}: {r.wall_s:.2f} s", flush=True)
    sim.save_checkpoint(path)
    meta.write_text(json.dumps({"first_cut_step": after_cut, "scene": scene_json}))
    return path, after_cut


def checkpoint(name: str, grid: str, warmup: int, removal: str = "threshold") -> Path:
    """The cached checkpoint of built-in scene ``name`` on ``grid`` (with the cut's
    ``removal``) two steps after its first cut (``warm_up``), made first when there is none."""
    tail = "" if removal == "threshold" else f"_{removal}"
    return warm_up(scene_on(name, grid, removal), CACHE / f"{name}_{grid}{tail}.h5", warmup)[0]


def scene_on(name: str, grid: str, removal: str = "threshold") -> Scene:
    """Built-in scene ``name`` on its own graded grid or on the uniform 33x33x65, with the cut's
    ``level_set.removal`` (every mode of a run steps the same scene)."""
    scene = builtin_scene(name)
    if removal != scene.level_set.removal:
        scene = scene.model_copy(
            update={"level_set": scene.level_set.model_copy(update={"removal": removal})}
        )
    return scene if grid == "own" else scene.on_uniform_grid(UNIFORM)


def load_as(path: Path, solver: dict[str, Any] | None = None, **mechanics: Any) -> Simulation:
    """The checkpoint continued with ``solver.incremental`` and mechanics settings changed
    (``incremental`` among them) and the ``solver`` section's keys given, exactly as
    ``Simulation.load_checkpoint`` continues it."""
    incremental = mechanics.pop("incremental", True)

    def variant(scene: Scene) -> Scene:
        data = scene.model_dump()
        data["solver"].update(solver or {})
        data["solver"]["incremental"] = incremental
        data["mechanics"].update(mechanics)
        return Scene.model_validate(data)

    return Simulation.load_checkpoint(path, scene=variant)


MODES: dict[str, dict[str, Any]] = {
    "full": {"incremental": False},
    "incremental": {},
    "cnn": {"backend": "cnn"},
    "persistence": {
        "guard": "residual",
        "guard_tolerance": 0.99,
        "correction": "none",
        "full_every": 10000,
    },
}
"""The modes, as mechanics settings. ``persistence`` is the trivial baseline every approximation
is read against: the last displacement, Ritz-scaled, taken as the step's answer (solved only where
there is none yet, the first mechanics step, or its relative residual passes 0.99)."""
TIGHT_MODE = "incremental, block polish"
"""``--tight``: the incremental mode without its windowed polish (``mechanics.polish_window_m``
0, as before 2026-12-03 10:00: every polish iteration over the whole block), beside the default."""
TIGHT: dict[str, Any] = {"polish_window_m": 0.0}


TOLERANCE_MODE = "incremental, energy_tolerance "
"""``--tolerances``: the incremental mode with ``mechanics.energy_tolerance`` set to the value
that follows this prefix in the mode's name."""


SETTINGS_MODE = "with "
"""``--variant``: the incremental mode with the scene settings that follow this prefix in the
mode's name, ``section.key=value`` joined by ``, `` (sections ``solver`` and ``mechanics``;
``solver.incremental=false`` makes it a full mode, e.g. the reference at a tighter tolerance)."""
VARIANT_SECTIONS = ("solver", "mechanics")


def parse_settings(spec: str) -> dict[str, dict[str, Any]]:
    """``"solver.electric_energy_tolerance=1e-4, mechanics.energy_tolerance=0.01"`` as
    {section: {key: value}}: values parsed as JSON where they are (numbers, true, null), else
    kept as text; a bad item raises ValueError naming it."""
    out: dict[str, dict[str, Any]] = {}
    for item in filter(None, (p.strip() for p in spec.split(","))):
        key, eq, text = item.partition("=")
        section, dot, name = key.strip().partition(".")
        if not eq or not dot or not name or section not in VARIANT_SECTIONS:
            raise ValueError(
                f"variant setting {item!r}: expected section.key=value with section one of "
                f"{', '.join(VARIANT_SECTIONS)}"
            )
        try:
            value: Any = json.loads(text.strip())
        except json.JSONDecodeError:
            value = text.strip()
        out.setdefault(section, {})[name] = value
    if not out:
        raise ValueError(f"variant {spec!r} sets nothing")
    return out


def check_settings(spec: str, scenes: list[str]) -> None:
    """Parse ``spec`` and apply it to each built-in scene named; a setting the scene model
    refuses (an unknown key, a value out of range) raises ValueError naming it."""
    settings = parse_settings(spec)
    for name in scenes:
        data = builtin_scene(name).model_dump()
        for section, values in settings.items():
            data[section].update(values)
        try:
            Scene.model_validate(data)
        except ValidationError as e:
            err = e.errors()[0]
            where = ".".join(str(p) for p in err["loc"])
            raise ValueError(f"variant {spec!r}: {where}: {err['msg']}") from None


def modes_for(
    scene: Scene,
    tight: bool = False,
    tolerances: tuple[float, ...] = (),
    variants: tuple[str, ...] = (),
) -> list[str]:
    """The modes that apply: the CNN only with mechanics on a grid with a shipped model;
    ``tight``: also ``TIGHT_MODE``, ``tolerances``: a mode per mechanics energy tolerance,
    where the scene has mechanics; ``variants``: a ``SETTINGS_MODE`` per settings spec (any
    scene)."""
    mech = "mechanics" in scene.closed_effects
    cnn = mech and scene.resolution is None and tuple(scene.grid) == UNIFORM
    extra = ([TIGHT_MODE] if tight else []) + [f"{TOLERANCE_MODE}{t:g}" for t in tolerances]
    settings = [f"{SETTINGS_MODE}{v}" for v in variants]
    base = [m for m in MODES if (m != "cnn" or cnn) and (m != "persistence" or mech)]
    return base + (extra if mech else []) + settings


def load_mode(path: Path, mode: str) -> Simulation:
    """The checkpoint continued in ``mode`` (a ``MODES`` key, ``TIGHT_MODE``, a
    ``TOLERANCE_MODE`` or a ``SETTINGS_MODE``)."""
    if mode.startswith(TOLERANCE_MODE):
        return load_as(path, energy_tolerance=float(mode.removeprefix(TOLERANCE_MODE)))
    if mode.startswith(SETTINGS_MODE):
        settings = parse_settings(mode.removeprefix(SETTINGS_MODE))
        solver = dict(settings.get("solver", {}))
        incremental = bool(solver.pop("incremental", True))
        return load_as(path, solver, incremental=incremental, **settings.get("mechanics", {}))
    return load_as(path, **(TIGHT if mode == TIGHT_MODE else MODES[mode]))


def run_modes(path: Path, modes: list[str], steps: int) -> dict[str, dict[str, list[float]]]:
    """Every mode from the checkpoint, stepped in lockstep; per mode the per-step records."""
    sims = {m: load_mode(path, m) for m in modes}
    keys = ("wall_s", "se_err", "dT_k", "tets_apart", "local", "cut_m3", *EFFECTS)
    rec: dict[str, dict[str, list[float]]] = {m: {k: [] for k in keys} for m in modes}
    for _ in range(steps):
        for m, sim in sims.items():
            r = sim.step()
            mech = r.effects.get("mechanics")
            rec[m]["wall_s"].append(r.wall_s)
            rec[m]["local"].append(
                float(mech is not None and mech.ran and mech.extra.get("mode") == "local")
            )
            rec[m]["cut_m3"].append(r.cut_volume_m3)
            for e in EFFECTS:
                eff = r.effects.get(e)
                rec[m][e].append(eff.wall_s if eff is not None and eff.ran else 0.0)
        ref = sims["full"].state
        for m, sim in sims.items():
            W, W_ref = sim.state["strain_energy"], ref["strain_energy"]
            rec[m]["se_err"].append(
                relative_strain_energy_error(W, W_ref) if W_ref is not None and W_ref.any() else 0.0
            )
            rec[m]["dT_k"].append(
                float(np.abs(sim.state["temperature"] - ref["temperature"]).max())
            )
            rec[m]["tets_apart"].append(
                float(np.count_nonzero(sim.state["removed"] != ref["removed"]))
            )
    return rec


def measure(
    scene: Scene,
    path: Path,
    *,
    warmup: int,
    steps: int,
    tight: bool = False,
    tolerances: tuple[float, ...] = (),
    variants: tuple[str, ...] = (),
    from_start: bool = False,
    from_step: int | None = None,
) -> dict[str, Any]:
    """``scene`` warmed up (checkpoint ``path``), then every mode that applies in lockstep;
    ``from_start``: from the scene's first step instead (the checkpoint holds step 0), so the
    steps span the heating, the first vaporization and mechanics solve, and the cut;
    ``from_step``: from the state after exactly that many steps in the scene's own settings."""
    if from_start:
        from_step = 0
    exact = from_step is not None
    path, first_cut = warm_up(scene, path, from_step if exact else warmup, exact=exact)
    return {
        "rec": run_modes(path, modes_for(scene, tight, tolerances, variants), steps),
        "dt_s": scene.dt_s,
        "first_cut": first_cut,
        "from_start": from_step == 0,
        "from_step": from_step,
        "nodes": int(np.prod(scene.node_shape)),
        "grid_label": "x".join(map(str, scene.node_shape))
        + (" graded" if scene.resolution is not None else " uniform"),
    }


def profile(a: argparse.Namespace, started: str) -> None:
    """The incremental mode's steps under cProfile: top functions by own time."""
    import cProfile
    import pstats

    removal = getattr(a, "removal", "threshold")
    flag = "" if removal == "threshold" else f" --removal {removal}"
    lines = [
        "# Real time: where a cutting step's time goes (incremental mode, cProfile)",
        "",
        f"`python benchmarks/realtime.py profile --scenes {' '.join(a.scenes)} --grids "
        f"{' '.join(a.grids)} --steps {a.steps}{flag}` (started {started}, load average "
        f"{os.getloadavg()[0]:.1f}): {a.steps} steps from the checkpoint two steps after the "
        "first cut; the profiler inflates every call alike. Own time: in the function itself; "
        "cumulative: with what it calls.",
        "",
    ]
    for name in a.scenes:
        for grid in a.grids:
            scene = scene_on(name, grid, removal)
            sim = load_as(checkpoint(name, grid, a.warmup, removal))
            prof = cProfile.Profile()
            prof.enable()
            for _ in range(a.steps):
                sim.step()
            prof.disable()
            st = pstats.Stats(prof)
            total = max(v[3] for v in st.stats.values())  # type: ignore[attr-defined]
            top = sorted(st.stats.items(), key=lambda kv: kv[1][2], reverse=True)[: a.top]  # type: ignore[attr-defined]
            label = "x".join(map(str, scene.node_shape))
            lines += [
                f"## {name}, {label} ({'graded' if scene.resolution is not None else 'uniform'})",
                "",
                f"{total / a.steps:.2f} s per step under the profiler.",
                "",
                "| function | calls | own s per step | share | cumulative s per step |",
                "|---|---|---|---|---|",
            ]
            for (file, line, fn), (_cc, nc, tt, ct, _callers) in top:
                where = file.split("site-packages/")[-1].split("/server/")[-1]
                lines.append(
                    f"| `{fn}` ({where}:{line}) | {nc} | {tt / a.steps:.3f} | "
                    f"{tt / total:.0%} | {ct / a.steps:.3f} |"
                )
            lines.append("")
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "realtime_profile.md").write_text("\n".join(lines))
    print("\n".join(lines))


def start_suffix(a: argparse.Namespace) -> str:
    """The checkpoint name's tail for ``a``'s starting point and removal (one file each)."""
    removal = "" if a.removal == "threshold" else f"_{a.removal}"
    if a.from_start:
        return f"{removal}_start"
    return removal if a.from_step is None else f"{removal}_step{a.from_step}"


def run_args(a: argparse.Namespace, scene: str, grid: str, out: Path) -> list[str]:
    """The ``run`` command line (after the script) that measures ``scene`` on ``grid`` alone
    with ``a``'s settings, its results in ``out``."""
    args = ["run", "--scenes", scene, "--grids", grid, "--steps", str(a.steps)]
    args += ["--warmup", str(a.warmup), "--out", str(out)]
    if a.from_start:
        args.append("--from-start")
    if a.from_step is not None:
        args += ["--from-step", str(a.from_step)]
    if a.tight:
        args.append("--tight")
    if a.removal != "threshold":
        args += ["--removal", a.removal]
    if a.tolerances:
        args += ["--tolerances", *map(repr, a.tolerances)]
    for v in a.variant:
        args += ["--variant", v]
    return args


def run_apart(a: argparse.Namespace, started: str) -> None:
    """Each (scene, grid) of ``a`` measured in a process of its own, the results merged into
    one table. In one process the memory of the larger grids' runs was not given back to the
    system between them: the default command (every scene on both grids) reached 22 GB on the
    moving-electrode-slow scene; a process per pair holds at most one pair's modes (about 10 GB on
    the moving electrode's 279 k nodes). A pair that fails stops the run with what was measured
    before it written."""
    import subprocess
    import tempfile

    runs: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        for n in a.scenes:
            for g in a.grids:
                out = Path(tmp) / f"{n}-{g}"
                cmd = [sys.executable, str(Path(__file__).resolve()), *run_args(a, n, g, out)]
                print(f"=== {n} on the {g} grid", flush=True)
                rc = subprocess.run(cmd).returncode
                if rc != 0:
                    if runs:
                        write_run(runs, a, started, a.out)
                    sys.exit(f"realtime.py: the run of {n} on the {g} grid failed (exit {rc})")
                runs.update(read_run(out)[0])
    write_run(runs, a, started, a.out)


def parser() -> argparse.ArgumentParser:
    """The command line of every subcommand."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    for cmd, help_, steps in (
        ("run", "full vs incremental per step, with the errors", 8),
        ("profile", "cProfile of the incremental mode's steps", 6),
        ("timers", "wall-clock timers around the parts of the incremental mode's steps", 8),
    ):
        r = sub.add_parser(cmd, help=help_)
        r.add_argument("--scenes", nargs="+", choices=SCENES, default=list(SCENES))
        r.add_argument("--grids", nargs="+", choices=("own", "uniform"), default=["own", "uniform"])
        r.add_argument("--steps", type=int, default=steps)
        r.add_argument("--warmup", type=int, default=60, help="steps at most before the cut")
        r.add_argument("--top", type=int, default=15, help="profile: functions listed")
        r.add_argument("--out", type=Path, default=RESULTS, help="results folder")
        r.add_argument(
            "--tight",
            action="store_true",
            help=f"run: also '{TIGHT_MODE}', the incremental mode without its windowed polish",
        )
        r.add_argument(
            "--tolerances",
            nargs="+",
            type=float,
            default=[],
            help="run: also the incremental mode at each of these mechanics.energy_tolerance",
        )
        r.add_argument(
            "--variant",
            action="append",
            default=[],
            metavar="SETTINGS",
            help="run: also the incremental mode (solver.incremental=false: the full one) with "
            "these scene settings, e.g. "
            "'solver.electric_energy_tolerance=1e-4, mechanics.energy_tolerance=0.01' "
            "(repeatable)",
        )
        r.add_argument(
            "--removal",
            choices=("threshold", "fraction"),
            default="threshold",
            help="the scenes' level_set.removal (run: for every mode)",
        )
        start = r.add_mutually_exclusive_group()
        start.add_argument(
            "--from-start",
            action="store_true",
            help="run: from the scene's first step (a whole run with --steps its steps) "
            "instead of two steps after the first cut",
        )
        start.add_argument(
            "--from-step",
            type=int,
            metavar="N",
            help="run: from the state after exactly N steps in the scene's own settings",
        )
    rp = sub.add_parser("report", help="rewrite a run's table and plots from its realtime.json")
    rp.add_argument("folder", type=Path, help="the run's --out folder")
    s = sub.add_parser("solvers", help="per-saving cost of a cutting step")
    s.add_argument("--grids", nargs="+", type=float, default=[0.0, 0.5], help="0: uniform")
    s.add_argument("--steps", type=int, default=6)
    s.add_argument("--rounds", type=int, default=1)
    return ap


def main() -> None:
    from diathermy.runtime import configure_threads

    configure_threads()  # as the CLI and the server run: one BLAS thread
    ap = parser()
    a = ap.parse_args()
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    if a.cmd == "run":
        if a.from_step is not None and a.from_step < 0:
            ap.error(f"--from-step: a step count, not {a.from_step}")
        for v in a.variant:  # a bad setting stops the run before any warm-up
            try:
                check_settings(v, a.scenes)
            except ValueError as e:
                ap.error(str(e))
        if len(a.scenes) * len(a.grids) > 1:
            run_apart(a, started)
            return
        runs = {
            (n, g): measure(
                scene_on(n, g, a.removal),
                CACHE / f"{n}_{g}{start_suffix(a)}.h5",
                warmup=a.warmup,
                steps=a.steps,
                tight=a.tight,
                tolerances=tuple(a.tolerances),
                variants=tuple(a.variant),
                from_start=a.from_start,
                from_step=a.from_step,
            )
            for n in a.scenes
            for g in a.grids
        }
        write_run(runs, a, started, a.out)
        return
    if a.cmd == "profile":
        profile(a, started)
        return
    if a.cmd == "timers":
        from realtime_timers import timers  # the realtime.py timers subcommand

        timers(a, started, lambda n, g: load_as(checkpoint(n, g, a.warmup, a.removal)))
        return
    if a.cmd == "report":
        if not (a.folder / "realtime.json").is_file():
            ap.error(f"{a.folder}: no realtime.json (the --out folder of a 'run')")
        runs, command, when, load = read_run(a.folder)
        write_run(runs, command, when, a.folder, load)
        return
    from realtime_solvers import solvers  # the realtime.py solvers subcommand

    solvers(a, started)


if __name__ == "__main__":
    main()
