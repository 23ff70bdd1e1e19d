"""The memory estimate the service checks grids against, against a measured peak RSS."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from diathermy.engine.limits import estimate_memory_bytes

ROOT = Path(__file__).resolve().parents[2]

# VmHWM, not getrusage's ru_maxrss: Linux carries ru_maxrss across exec from the forked parent
# (here a pytest process that may be far bigger than the child), VmHWM starts afresh.
CHILD = """
import json, sys
from pathlib import Path
def rss(key="VmRSS:"):
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key):
            return int(line.split()[1]) * 1024
from diathermy.engine.simulation import Simulation
from diathermy.runtime import configure_threads
from diathermy.scene import scene_from_dict
configure_threads()
scene = scene_from_dict({"block_m": [0.02, 0.01, 0.01], "grid": %r, "effects": %r,
                         "electrodes": [{"position_m": [0.01, 0.005], "power_w": 200.0}]})
base = rss()
sim = Simulation(scene)
reports = sim.run(3)
peak = rss("VmHWM:")
print(json.dumps({"bytes": peak - base, "mechanics": any(r.ran("mechanics") for r in reports)}))
"""


def measured_bytes(grid: tuple[int, int, int], effects: list[str]) -> tuple[int, bool]:
    """Peak RSS of building and stepping one simulation, above the process after imports."""
    out = subprocess.run(
        [sys.executable, "-c", CHILD % (list(grid), effects)],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
        env={"PYTHONPATH": str(ROOT / "server"), "PATH": "/usr/bin:/bin"},
    )
    got = json.loads(out.stdout.strip().splitlines()[-1])
    return int(got["bytes"]), bool(got["mechanics"])


@pytest.mark.parametrize(
    "effects", [["electric", "thermal"], ["electric", "thermal", "mechanics", "dissection"]]
)
def test_estimate_is_within_2x_of_the_measured_peak(effects: list[str]) -> None:
    grid = (13, 13, 25)
    measured, mechanics_ran = measured_bytes(grid, effects)
    assert mechanics_ran == ("mechanics" in effects)  # the expensive part really ran
    estimate = estimate_memory_bytes(grid, effects)
    assert measured / 2 <= estimate <= 2 * measured, (estimate / 2**20, measured / 2**20)


def test_estimate_grows_with_nodes_and_with_mechanics() -> None:
    small, big = (9, 9, 17), (33, 33, 65)
    et = ["electric", "thermal"]
    assert estimate_memory_bytes(big, et) > estimate_memory_bytes(small, et)
    # 'dissection' implies mechanics: the closure counts, not the list as given
    assert estimate_memory_bytes(small, ["dissection"]) > estimate_memory_bytes(small, et)
    # the paper's 64 x 64 x 128 grid with every effect needs several GiB
    assert estimate_memory_bytes((64, 64, 128), ["dissection"]) > 4 * 2**30
