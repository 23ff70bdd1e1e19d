"""Scenarios on Dask (``pip install diathermy[cluster]``): a local cluster or an existing one.

Why Dask rather than Ray: pure-Python wheels (no raylet, object store or shared-memory daemon to
fit on a 2-core machine), a LocalCluster that starts in about a second for tests, and the same
``Client(address)`` reaches the HPC schedulers our users have (SLURM/PBS via dask-jobqueue).
Tasks return only a shard path, so no sample crosses the network; on a real cluster the shard
folder must be on a file system the workers and this process share.
"""

from __future__ import annotations

import uuid
from collections.abc import Sequence

from diathermy.datagen.runners import ResultStream, Runner, compute_shard
from diathermy.datagen.scenario import PhysicsFactory
from diathermy.errors import DiathermyError


def _client(address: str | None, workers: int):  # -> distributed.Client
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise DiathermyError(
            "the dask engine needs the 'cluster' extra: pip install 'diathermy[cluster]'"
        ) from None
    if address is not None:
        return Client(address), None
    cluster = LocalCluster(
        n_workers=workers,
        threads_per_worker=1,  # our solves are single-threaded; one scenario per process
        processes=True,
        dashboard_address=None,
        scheduler_port=0,
        host="127.0.0.1",
    )
    return Client(cluster), cluster


def dask_runner(address: str | None = None) -> Runner:
    """A runner over a Dask cluster at ``address``, or a fresh local one of ``workers``."""

    def run(
        config_json: str,
        indices: Sequence[int],
        shard_dir: str,
        factory: PhysicsFactory,
        workers: int,
    ) -> ResultStream:
        from distributed import as_completed

        client, cluster = _client(address, workers)
        run_id = uuid.uuid4().hex[:8]  # keys unique on a shared scheduler
        try:
            futures = {
                client.submit(
                    compute_shard,
                    config_json,
                    i,
                    shard_dir,
                    factory,
                    key=f"datagen-{run_id}-{i}",
                    pure=False,
                ): i
                for i in indices
            }
            try:
                for fut in as_completed(futures):
                    yield futures[fut], fut.result()
            finally:
                client.cancel(list(futures))
        finally:
            client.close()
            if cluster is not None:
                cluster.close()

    return run
