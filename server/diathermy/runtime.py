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
    n = os.environ.get("DIATHERMY_BLAS_THREADS", "1")
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, n)  # for pools loaded later (threadpoolctl sees loaded ones)
    # scipy ships its own OpenBLAS, loaded with scipy.linalg: load it now so the limit reaches it
    # (unlimited, pyamg's dense coarse solve (pinv) ran up to 40x slower on a busy 2-core machine)
    import scipy.linalg  # noqa: F401

    threadpool_limits(int(n))
    _applied = True
