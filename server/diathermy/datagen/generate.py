"""Run Algorithm 1's scenarios on local processes (default) or Dask, and commit them in order.

Workers compute whole scenarios and write each to a shard file; the parent, the dataset's only
writer, copies shards in scenario order, so the file is the same whatever the engine and the
number of workers, and a resume reuses shards that finished but were not yet copied.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import h5py

from diathermy.datagen.config import DatagenConfig
from diathermy.datagen.runners import (
    Runner,
    run_in_process,
    run_local_pool,
    shard_path,
)
from diathermy.datagen.scenario import PhysicsFactory
from diathermy.datagen.storage import (
    SHARD_FORMAT,
    DatasetWriter,
    check_config,
    check_layout,
)
from diathermy.errors import CheckpointError

Engine = Literal["local", "dask"]
ENGINES: tuple[str, ...] = ("local", "dask")


@dataclass(frozen=True)
class GenerateSummary:
    """What a call to ``generate`` did."""

    path: Path
    engine: str
    workers: int
    complete_scenarios: int
    computed_scenarios: int
    reused_shards: int
    samples: int
    wall_s: float


def default_physics_factory() -> PhysicsFactory:
    """The FEM mechanics + level-set physics (imported late: heavy)."""
    from diathermy.datagen.physics import fem_physics

    return fem_physics


def shard_dir_for(out: Path) -> Path:
    """Where the shards of dataset ``out`` live while it is generated."""
    return out.with_name(out.name + ".shards")


def _valid_shard(path: Path, config: DatagenConfig, index: int) -> bool:
    try:
        with h5py.File(path, "r") as f:
            check_layout(f, path, SHARD_FORMAT)
            check_config(f, path, config)
            return int(f.attrs["scenario_index"]) == index
    except (OSError, CheckpointError, KeyError):
        return False


def _prepare_shards(shard_dir: Path, config: DatagenConfig, first: int) -> set[int]:
    """Remove stale and torn shards; return the indices of whole shards still to copy."""
    shard_dir.mkdir(parents=True, exist_ok=True)
    for tmp in shard_dir.glob("*.tmp"):
        tmp.unlink()
    ready = set()
    for path in shard_dir.glob("scenario_*.h5"):
        index = int(path.stem.removeprefix("scenario_"))
        if first <= index < config.n_scenarios and _valid_shard(path, config, index):
            ready.add(index)
        else:
            path.unlink()
    return ready


def generate(
    config: DatagenConfig,
    out: str | Path,
    *,
    engine: Engine = "local",
    workers: int | None = None,
    resume: bool = False,
    factory: PhysicsFactory | None = None,
    on_commit: Callable[[int], None] | None = None,
    scheduler_address: str | None = None,
) -> GenerateSummary:
    """Generate (or finish) the dataset of ``config`` in ``out``; returns a summary.

    ``on_commit(index)`` runs after each scenario is committed (progress bars; an exception
    from it stops the run with everything committed so far kept).
    """
    t0 = time.perf_counter()
    out = Path(out)
    workers = workers or config.workers
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    writer = DatasetWriter(out, config, resume=resume)
    factory = factory or default_physics_factory()
    shard_dir = shard_dir_for(out)
    first = writer.complete_scenarios
    ready = _prepare_shards(shard_dir, config, first)
    reused = len(ready)
    to_compute = [i for i in range(first, config.n_scenarios) if i not in ready]
    runner = _runner(engine, workers, scheduler_address)
    stream = runner(config.model_dump_json(), to_compute, str(shard_dir), factory, workers)
    computed = 0
    try:
        _commit_ready(writer, ready, shard_dir, on_commit)
        for index, _path in stream:
            computed += 1
            ready.add(index)
            _commit_ready(writer, ready, shard_dir, on_commit)
    finally:
        close = getattr(stream, "close", None)
        if close is not None:
            close()
    if writer.complete_scenarios == config.n_scenarios and not any(shard_dir.iterdir()):
        shard_dir.rmdir()
    return GenerateSummary(
        path=out,
        engine=engine,
        workers=workers,
        complete_scenarios=writer.complete_scenarios,
        computed_scenarios=computed,
        reused_shards=reused,
        samples=writer.complete_scenarios * config.n_steps,
        wall_s=time.perf_counter() - t0,
    )


def _commit_ready(
    writer: DatasetWriter,
    ready: set[int],
    shard_dir: Path,
    on_commit: Callable[[int], None] | None,
) -> None:
    """Copy the shards that continue the committed prefix, in order, and delete them."""
    while writer.complete_scenarios in ready:
        index = writer.complete_scenarios
        path = shard_path(shard_dir, index)
        writer.append_shard(path)
        ready.discard(index)
        path.unlink()
        if on_commit is not None:
            on_commit(index)


def _runner(engine: str, workers: int, scheduler_address: str | None) -> Runner:
    if engine == "dask":
        from diathermy.datagen.distributed import dask_runner

        return dask_runner(scheduler_address)
    return run_in_process if workers == 1 else run_local_pool
