"""Process-wide runtime settings applied by the entry points (CLI, server, tests)."""

from __future__ import annotations

import os

from threadpoolctl import threadpool_limits

_applied = False


def configure_threads() -> None:
    """Limit BLAS/OpenMP pools to ``DIATHERMY_BLAS_THREADS`` (default 1).

    The solvers are sparse and memory-bound; a multi-threaded OpenBLAS only adds contention on
    small, shared machines (3-6x slower CG and AMG setup measured on 2 cores).
    """
    global _applied
    if _applied:
        return
    threadpool_limits(int(os.environ.get("DIATHERMY_BLAS_THREADS", "1")))
    _applied = True
