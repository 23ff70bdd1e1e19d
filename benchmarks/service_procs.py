"""What the service benchmark reads of its processes (``/proc``): CPU seconds, resident
memory, the engines' run-queue delay, and the host's steal time (Linux only)."""

from __future__ import annotations

import os
import resource
from pathlib import Path


def rss_mib(pid: int) -> tuple[float, float]:
    """(current, peak) resident set of a process in MiB."""
    status = Path(f"/proc/{pid}/status").read_text()
    val = {ln.split(":")[0]: ln.split()[1] for ln in status.splitlines() if ln.startswith("Vm")}
    return int(val["VmRSS"]) / 1024, int(val["VmHWM"]) / 1024


def cpu_s(pid: int) -> float:
    """CPU seconds (user + system, all threads) a process has used."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def children_cpu_s() -> float:
    """CPU seconds of the benchmark's client processes that have ended (forked and joined)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def descendants(pid: int) -> list[int]:
    """Child processes of ``pid``, recursively (the forkserver and the engine processes)."""
    out: list[int] = []
    for task in Path(f"/proc/{pid}/task").glob("*/children"):
        for child in task.read_text().split():
            out += [int(child), *descendants(int(child))]
    return out


def cpu_ticks() -> tuple[int, int]:
    """(steal, total) clock ticks of all CPUs so far (``/proc/stat``): steal is the time the
    hypervisor ran other virtual machines on this one's CPUs."""
    fields = [int(x) for x in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    return fields[7], sum(fields[:8])


def steal_share(start: tuple[int, int]) -> float:
    """Share of the CPUs' time since ``start`` (``cpu_ticks``) that the host took."""
    steal, total = cpu_ticks()
    return (steal - start[0]) / max(1, total - start[1])


def run_queue_s(pid: int) -> float:
    """Seconds the processes under ``pid`` (the engines) spent runnable but waiting for a CPU
    (``/proc/<pid>/schedstat``, main threads)."""
    total = 0.0
    for child in descendants(pid):
        try:
            total += int(Path(f"/proc/{child}/schedstat").read_text().split()[1]) / 1e9
        except (FileNotFoundError, ProcessLookupError, IndexError):
            continue
    return total


def tree_cpu_s(pid: int) -> tuple[float, dict[int, float]]:
    """(CPU seconds of ``pid``, {descendant pid: its CPU seconds})."""
    kids = {}
    for child in descendants(pid):
        try:
            kids[child] = cpu_s(child)
        except (FileNotFoundError, ProcessLookupError):
            continue
    return cpu_s(pid), kids
