"""Process-wide runtime settings applied by the entry points (CLI, server, tests)."""

from __future__ import annotations

import os
import resource
from pathlib import Path

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


def own_peak_rss_mib() -> float:
    """This process's own peak resident memory in MiB (Linux: ``VmHWM`` of ``/proc/self/status``).

    ``getrusage(RUSAGE_SELF).ru_maxrss`` is not that for a spawned process: Linux keeps the
    high-water mark of the address space an ``exec`` replaces, and a spawned child starts as a
    fork of its parent, so it reports at least the parent's resident memory at the spawn (every
    variant the accuracy-cost report ran after its driver held 1.2 GiB read 1234 MB). Elsewhere
    ``ru_maxrss`` (kB on Linux, bytes on macOS) is the fallback.
    """
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if os.uname().sysname == "Darwin" else peak / 1024.0
