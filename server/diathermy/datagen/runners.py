"""Where scenarios run: one after another in this process or on a pool of local processes
(the Dask runner lives in ``distributed``). Each task runs one whole scenario into a shard file."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from pathlib import Path

from threadpoolctl import threadpool_limits

from diathermy.datagen.config import DatagenConfig
from diathermy.datagen.scenario import PhysicsFactory, run_scenario
from diathermy.datagen.storage import write_shard


def shard_path(shard_dir: Path, index: int) -> Path:
    return shard_dir / f"scenario_{index:06d}.h5"


def compute_shard(config_json: str, index: int, shard_dir: str, factory: PhysicsFactory) -> str:
    """Worker task: run scenario ``index`` and write its shard; returns the shard path."""
    config = DatagenConfig.model_validate_json(config_json)
    path = shard_path(Path(shard_dir), index)
    # Parallelism is over scenarios: BLAS threads only oversubscribe the cores (measured 1.5-3x
    # slower at 17x17x33 with OpenBLAS's default threads, benchmarks/datagen.py).
    with threadpool_limits(limits=1):
        physics = factory(config)
        write_shard(path, config, index, run_scenario(config, index, physics))
    return str(path)


ResultStream = Iterator[tuple[int, str]]
Runner = Callable[[str, Sequence[int], str, PhysicsFactory, int], ResultStream]


def run_in_process(
    config_json: str, indices: Sequence[int], shard_dir: str, factory: PhysicsFactory, workers: int
) -> ResultStream:
    """Scenarios one after another in this process."""
    for i in indices:
        yield i, compute_shard(config_json, i, shard_dir, factory)


def run_local_pool(
    config_json: str, indices: Sequence[int], shard_dir: str, factory: PhysicsFactory, workers: int
) -> ResultStream:
    """Scenarios on a pool of local processes, at most 2 per worker in flight (bounded shards)."""
    pending: dict[Future[str], int] = {}
    todo = list(indices)
    with ProcessPoolExecutor(max_workers=workers) as pool:
        try:
            while todo or pending:
                while todo and len(pending) < 2 * workers:
                    i = todo.pop(0)
                    pending[pool.submit(compute_shard, config_json, i, shard_dir, factory)] = i
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in sorted(done, key=pending.__getitem__):
                    yield pending.pop(fut), fut.result()
        finally:
            for fut in pending:
                fut.cancel()
