"""A second training source beside Algorithm 1: (p, phi, u) recorded from FEM engine runs.

Algorithm 1's random walks give pressure on scattered surface tets; the engine's EOS gives smooth
pressure domes under an electrode and craters/trenches in phi. A model trained on the walks alone
generalises poorly to those fields (benchmarks/results/hybrid.md), so this module runs the full
engine (FEM mechanics) on random electrode scenes -- random power, start point, direction and
speed, some held still -- and records every ``record_every``-th step whose mechanics ran. The
built-in fixed- and moving-electrode scenes are never generated (they are the held-out test).

Output: the ``diathermy-dataset`` v1 layout (``/pressure``, ``/level_set``, ``/displacement``,
``/scenario``, ``/step``), one scenario per run, so ``diathermy train`` reads it directly;
``merge_datasets`` concatenates it with an Algorithm 1 file.

    python -m diathermy.datagen.engine_samples --out engine.h5 --runs 3 --steps 70
    python -m diathermy.datagen.engine_samples --merge alg1.h5 engine.h5 --out train.h5
    python -m diathermy.datagen.engine_samples --scene fixed-electrode --steps 400 --out test.h5
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from diathermy.errors import CheckpointError, DiathermyError
from diathermy.version import __version__

FIELDS = ("pressure", "level_set", "displacement")


@dataclass(frozen=True)
class EngineSamplesConfig:
    """Random electrode scenes on one grid; ranges are uniform (power W, speed m/s)."""

    grid: tuple[int, int, int] = (33, 33, 65)
    block_m: tuple[float, float, float] = (0.2, 0.1, 0.1)
    n_runs: int = 3
    n_steps: int = 70
    record_every: int = 2
    power_w: tuple[float, float] = (30.0, 70.0)
    speed_m_per_s: tuple[float, float] = (0.0, 20e-3)
    still_fraction: float = 0.34  # share of runs with the electrode held still
    margin_m: float = 0.02  # start points keep this far from the block's sides
    seed: int = 0


def random_scene(config: EngineSamplesConfig, index: int):  # noqa: ANN201 (Scene: lazy import)
    """Run ``index``'s scene: power, start, direction and speed drawn from (seed, index)."""
    from diathermy.scene import Electrode, ElectrodePath, Scene

    rng = np.random.default_rng([config.seed, index])
    lx, ly, _ = config.block_m
    m = config.margin_m
    start = (float(rng.uniform(m, lx - m)), float(rng.uniform(m, ly - m)))
    power = float(rng.uniform(*config.power_w))
    still = rng.uniform() < config.still_fraction
    path = None
    if not still:
        speed = float(rng.uniform(max(config.speed_m_per_s[0], 1e-3), config.speed_m_per_s[1]))
        length = speed * config.n_steps * 0.03
        angle = float(rng.uniform(0, 2 * math.pi))
        end = (
            float(np.clip(start[0] + length * math.cos(angle), m, lx - m)),
            float(np.clip(start[1] + length * math.sin(angle), m, ly - m)),
        )
        if math.dist(start, end) > 1e-3:
            path = ElectrodePath(waypoints_m=[start, end], speed_m_per_s=speed)
    return Scene(
        name=f"engine-sample-{config.seed}-{index}",
        description="random electrode scene recorded for CNN training",
        grid=config.grid,
        block_m=config.block_m,
        electrodes=[Electrode(position_m=start, power_w=power, path=path)],
        steps=config.n_steps,
    )


def record_run(
    config: EngineSamplesConfig, index: int, *, progress: bool = False
) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
    """The recorded steps of random scene ``index`` (see :func:`record_scene`)."""
    scene = random_scene(config, index)
    return record_scene(scene, config.n_steps, config.record_every, progress=progress)


def record_scene(
    scene: Any, n_steps: int, record_every: int, *, progress: bool = False
) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
    """(step, p (nz, ny, nx) Pa, phi (nz, ny, nx) m, u (nz, ny, nx, 3) m) of every
    ``record_every``-th step of a FEM run of ``scene`` whose mechanics ran.

    phi is the level set the mechanics saw (before this step's dissection moved it);
    ``progress`` shows a bar over the steps.
    """
    from tqdm import tqdm

    from diathermy.engine.simulation import Simulation

    sim = Simulation(scene.model_copy(update={"steps": n_steps}))
    grid = sim.disc.grid.shape
    seen = 0
    for _ in tqdm(range(n_steps), desc=scene.name, unit="step", disable=not progress):
        phi = sim.state["level_set"].copy()
        rep = sim.step()
        if not rep.ran("mechanics"):
            continue
        seen += 1
        if (seen - 1) % record_every == 0:
            yield (
                rep.step,
                sim.state["pressure"].reshape(grid).copy(),
                phi.reshape(grid),
                sim.state["displacement"].reshape(*grid, 3).copy(),
            )


def _create(
    f: h5py.File, grid: tuple[int, int, int], spacing: Sequence[float], attrs: dict
) -> None:
    f.attrs.update(
        format="diathermy-dataset",
        format_version=1,
        diathermy_version=__version__,
        grid_shape=np.asarray(grid),
        spacing_m=np.asarray(spacing, float),
        complete_rows=0,
        complete_scenarios=0,
        **attrs,
    )
    for name in FIELDS:
        shape = (*grid, 3) if name == "displacement" else grid
        f.create_dataset(
            name, shape=(0, *shape), maxshape=(None, *shape), dtype="float32",
            chunks=(1, *shape), compression="gzip", compression_opts=4, shuffle=True,
        )  # fmt: skip
    for name in ("scenario", "step"):
        f.create_dataset(name, shape=(0,), maxshape=(None,), dtype="i8", chunks=(4096,))


def _append(f: h5py.File, rows: list[tuple[int, int, np.ndarray, np.ndarray, np.ndarray]]) -> None:
    n0 = int(f.attrs["complete_rows"])
    n = n0 + len(rows)
    for name in (*FIELDS, "scenario", "step"):
        f[name].resize(n, axis=0)
    for i, (scen, step, p, phi, u) in enumerate(rows):
        f["pressure"][n0 + i] = p
        f["level_set"][n0 + i] = phi
        f["displacement"][n0 + i] = u
        f["scenario"][n0 + i] = scen
        f["step"][n0 + i] = step
    f.flush()
    f.attrs["complete_rows"] = n  # the commit marker goes up only after the rows are written
    f.attrs["complete_scenarios"] = int(rows[-1][0]) + 1 if rows else f.attrs["complete_scenarios"]


def _material_json() -> str:
    from dataclasses import asdict as _asdict

    from diathermy.physics.materials import Tissue

    return json.dumps(_asdict(Tissue()))


def write_engine_samples(config: EngineSamplesConfig, out: str | Path, *, log: bool = True) -> int:
    """Run ``config.n_runs`` random scenes with FEM mechanics into ``out``; returns the row count."""
    from diathermy.mesh import Grid

    out = Path(out)
    spacing = Grid(config.grid, size_m=config.block_m).spacing_m
    attrs = {
        "config": json.dumps({"source": "engine_samples", **asdict(config)}, sort_keys=True),
        "material": _material_json(),
        "p0_pa": 101325.0,
    }
    t0 = time.perf_counter()
    with h5py.File(out, "w") as f:
        _create(f, config.grid, spacing, attrs)
        for run in range(config.n_runs):
            rows = [(run, s, p, phi, u) for s, p, phi, u in record_run(config, run, progress=log)]
            if rows:
                _append(f, rows)
            if log:
                print(
                    f"run {run}: {len(rows)} samples, {time.perf_counter() - t0:.0f} s", flush=True
                )
        return int(f.attrs["complete_rows"])


def write_scene_samples(
    names: Sequence[Any],
    out: str | Path,
    *,
    n_steps: int,
    record_every: int = 1,
    grid: tuple[int, int, int] | None = None,
    log: bool = True,
) -> int:
    """Record scenes (built-in names or Scene objects; one scenario each, in order) into ``out``.

    Returns the row count.
    The surrogates' held-out test set: ``diathermy evaluate MODEL out.h5`` then scores a model on
    the benchmark scenes without re-running the FEM.
    """
    from diathermy.mesh import Grid
    from diathermy.scene import builtin_scene, scene_from_dict

    scenes = [builtin_scene(n) if isinstance(n, str) else n for n in names]
    if grid is not None:  # validated like a scene file's grid; a uniform grid drops resolution
        scenes = [
            scene_from_dict({**s.model_dump(), "grid": list(grid), "resolution": None})
            for s in scenes
        ]
    graded = [s.name for s in scenes if s.resolution is not None]
    if graded:  # datasets (and the CNN that learns from them) live on uniform grids
        raise ValueError(
            f"scene(s) {', '.join(graded)} use a graded grid (resolution): dataset samples are "
            "recorded on uniform grids only; give --grid NZ NY NX"
        )
    if not scenes or any(
        (s.grid, s.block_m) != (scenes[0].grid, scenes[0].block_m) for s in scenes
    ):
        raise ValueError("give one or more built-in scenes of one grid and block")
    shape, block = tuple(scenes[0].grid), tuple(scenes[0].block_m)
    attrs = {
        "config": json.dumps(
            {
                "source": "engine_samples",
                "scenes": [s.name for s in scenes],
                "steps": n_steps,
                "record_every": record_every,
            },
            sort_keys=True,
        ),
        "material": _material_json(),
        "p0_pa": 101325.0,
    }
    t0 = time.perf_counter()
    with h5py.File(Path(out), "w") as f:
        _create(f, shape, Grid(shape, size_m=block).spacing_m, attrs)
        for run, scene in enumerate(scenes):
            rows = [
                (run, s, p, phi, u)
                for s, p, phi, u in record_scene(scene, n_steps, record_every, progress=log)
            ]
            if rows:
                _append(f, rows)
            if log:
                print(
                    f"{scene.name}: {len(rows)} samples, {time.perf_counter() - t0:.0f} s",
                    flush=True,
                )
        return int(f.attrs["complete_rows"])


def merge_datasets(inputs: Sequence[str | Path], out: str | Path) -> int:
    """Concatenate dataset files of one grid into ``out`` (scenarios renumbered); returns rows."""
    out = Path(out)
    grid = spacing = None
    offset = 0
    with h5py.File(out, "w") as g:
        for path in inputs:
            with h5py.File(path, "r") as f:
                if f.attrs.get("format") != "diathermy-dataset":
                    raise CheckpointError(f"{path} is not a diathermy dataset")
                n = int(f.attrs.get("complete_rows", f["pressure"].shape[0]))
                shape = tuple(int(s) for s in f["pressure"].shape[1:])
                sp = tuple(float(s) for s in f.attrs["spacing_m"])
                if grid is None:
                    grid, spacing = shape, sp
                    attrs = {
                        "config": json.dumps({"merged": [str(p) for p in inputs]}),
                        "p0_pa": float(f.attrs.get("p0_pa", 101325.0)),
                    }
                    if "material" in f.attrs:
                        attrs["material"] = f.attrs["material"]
                    elif "config" in f.attrs:
                        material = json.loads(f.attrs["config"]).get("material")
                        if material:
                            attrs["material"] = json.dumps(material)
                    _create(g, grid, spacing, attrs)  # type: ignore[arg-type]
                elif shape != grid or not np.allclose(sp, spacing):  # type: ignore[arg-type]
                    raise CheckpointError(f"{path}: grid {shape} differs from {grid}")
                scen = np.asarray(f["scenario"][:n], np.int64)
                ids = np.unique(scen)
                renum = np.searchsorted(ids, scen) + offset
                step = np.asarray(f["step"][:n], np.int64)
                for i in range(n):
                    _append(
                        g,
                        [
                            (
                                int(renum[i]), int(step[i]), f["pressure"][i],
                                f["level_set"][i], f["displacement"][i],
                            )
                        ],
                    )  # fmt: skip
                offset += ids.size
        return int(g.attrs["complete_rows"])


def main(argv: Sequence[str] | None = None) -> int:
    """CLI: record engine samples, or merge dataset files (see the module docstring)."""
    a = argparse.ArgumentParser(prog="python -m diathermy.datagen.engine_samples")
    a.add_argument("--out", required=True)
    a.add_argument("--merge", nargs="+", help="dataset files to concatenate instead")
    a.add_argument("--scene", nargs="+", help="record these built-in scenes instead of random ones")
    a.add_argument("--runs", type=int, default=EngineSamplesConfig.n_runs)
    a.add_argument("--steps", type=int, default=EngineSamplesConfig.n_steps)
    a.add_argument("--every", type=int, default=EngineSamplesConfig.record_every)
    a.add_argument("--grid", type=int, nargs=3, default=EngineSamplesConfig.grid)
    a.add_argument("--seed", type=int, default=EngineSamplesConfig.seed)
    a.add_argument(
        "--power", type=float, nargs=2, default=EngineSamplesConfig.power_w, metavar=("MIN", "MAX"),
        help="electrode power range, W",
    )  # fmt: skip
    a.add_argument(
        "--speed", type=float, nargs=2, default=EngineSamplesConfig.speed_m_per_s,
        metavar=("MIN", "MAX"), help="electrode speed range, m/s",
    )  # fmt: skip
    a.add_argument("--still-fraction", type=float, default=EngineSamplesConfig.still_fraction)
    args = a.parse_args(argv)
    from diathermy.runtime import configure_threads

    configure_threads()
    try:
        n = _run_cli(args)
    except (DiathermyError, ValueError, OSError) as err:  # one line, no traceback
        a.exit(2, f"{a.prog}: error: {err}\n")
    print(f"{args.out}: {n} samples")
    return 0


def _run_cli(args: argparse.Namespace) -> int:
    if args.merge:
        return merge_datasets(args.merge, args.out)
    if args.scene:
        return write_scene_samples(
            args.scene, args.out, n_steps=args.steps, record_every=args.every,
            grid=tuple(args.grid) if args.grid != EngineSamplesConfig.grid else None,
        )  # fmt: skip
    cfg = EngineSamplesConfig(
        grid=tuple(args.grid), n_runs=args.runs, n_steps=args.steps,
        record_every=args.every, seed=args.seed, power_w=tuple(args.power),
        speed_m_per_s=tuple(args.speed), still_fraction=args.still_fraction,
    )  # fmt: skip
    return write_engine_samples(cfg, args.out)


if __name__ == "__main__":
    raise SystemExit(main())
