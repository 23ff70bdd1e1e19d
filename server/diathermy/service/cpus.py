"""CPU placement (``DIATHERMY_ENGINE_CPUS``, ``diathermy serve --engine-cpus``): the engine
processes run on the CPUs listed, the server process (event loop, worker threads, the kernel's
socket copies it makes, the forkserver) on the CPUs it may use less those, so that an engine
never waits for a core that the fan-out of frames to many clients takes.

Unset (the default) places nothing: every process runs wherever the scheduler puts it.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path


def allowed_cpus() -> set[int]:
    """The CPUs this process may run on."""
    return set(os.sched_getaffinity(0))


def format_cpus(cpus: Iterable[int]) -> str:
    """``[0, 1, 2, 5]`` -> ``"0-2,5"``."""
    out: list[str] = []
    run: list[int] = []
    for c in sorted(set(cpus)):
        if run and c == run[-1] + 1:
            run.append(c)
            continue
        if run:
            out.append(str(run[0]) if len(run) == 1 else f"{run[0]}-{run[-1]}")
        run = [c]
    if run:
        out.append(str(run[0]) if len(run) == 1 else f"{run[0]}-{run[-1]}")
    return ",".join(out)


def parse_cpus(text: str) -> list[int]:
    """A CPU list as ``taskset -c`` takes it (``"3"``, ``"2,3"``, ``"2-5,8"``), sorted; an empty
    text is no placement. ValueError (one line) when it is not one."""
    cpus: set[int] = set()
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        lo, sep, hi = part.partition("-")
        try:
            first = int(lo)
            last = int(hi) if sep else first
        except ValueError:
            raise ValueError(
                f"not a CPU list: {text!r} (give CPU numbers and ranges, e.g. '1' or '2-3,6')"
            ) from None
        if first < 0 or last < first:
            raise ValueError(f"not a CPU range: {part!r} in {text!r}")
        cpus.update(range(first, last + 1))
    return sorted(cpus)


def check_engine_cpus(cpus: Iterable[int], allowed: set[int] | None = None) -> list[int]:
    """``cpus`` if each is one this process may run on and at least one is left for the server;
    else ValueError (one line)."""
    cpus = sorted(set(cpus))
    if not cpus:
        return cpus
    if allowed is None and not hasattr(os, "sched_setaffinity"):
        raise ValueError("engine CPU placement needs os.sched_setaffinity (Linux)")
    allowed = allowed_cpus() if allowed is None else allowed
    missing = [c for c in cpus if c not in allowed]
    if missing:
        raise ValueError(
            f"engine CPU(s) {format_cpus(missing)} not among the CPUs this process may run on "
            f"({format_cpus(allowed)})"
        )
    if not allowed - set(cpus):
        raise ValueError(
            f"engine CPUs {format_cpus(cpus)} leave no CPU for the server (it may run on "
            f"{format_cpus(allowed)} only)"
        )
    return cpus


def server_cpus(engine_cpus: Iterable[int]) -> set[int]:
    """The CPUs the server keeps when the engines take ``engine_cpus``."""
    return allowed_cpus() - set(engine_cpus)


def place_server(engine_cpus: Iterable[int]) -> set[int] | None:
    """Pin every thread of this process to the CPUs left by ``engine_cpus`` (threads and
    processes started later inherit it); None, and nothing changed, when ``engine_cpus`` is
    empty. Call it in the server process before it serves (``diathermy serve`` does)."""
    engine = check_engine_cpus(engine_cpus)
    if not engine:
        return None
    keep = server_cpus(engine)
    for task in Path("/proc/self/task").iterdir():  # sched_setaffinity(0) is one thread's
        try:
            os.sched_setaffinity(int(task.name), keep)
        except (ProcessLookupError, FileNotFoundError):  # a thread that just ended
            continue
    return keep


def place_engine(cpus: Iterable[int]) -> None:
    """Pin the calling engine process (its one thread, before it starts others) to ``cpus``;
    nothing when empty."""
    cpus = set(cpus)
    if cpus:
        os.sched_setaffinity(0, cpus)
