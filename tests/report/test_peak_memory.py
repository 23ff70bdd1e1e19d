"""The accuracy-cost report's peak memory is each variant's own, not its parent's."""

from __future__ import annotations

import multiprocessing as mp
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from diathermy.runtime import own_peak_rss_mib


def _child_peak(mib: int) -> float:
    """A spawned child that touches ``mib`` MiB and reports its peak."""
    block = np.ones(mib * 2**20 // 8)
    return own_peak_rss_mib() + 0.0 * float(block[-1])


def test_a_spawned_child_reports_its_own_peak_not_its_parents() -> None:
    held = np.ones(400 * 2**20 // 8)  # the parent holds 400 MiB while it spawns
    parent = own_peak_rss_mib()
    assert parent >= 400
    ctx = mp.get_context("spawn")
    with ProcessPoolExecutor(max_workers=1, mp_context=ctx, max_tasks_per_child=1) as pool:
        small = pool.submit(_child_peak, 10).result()
    with ProcessPoolExecutor(max_workers=1, mp_context=ctx, max_tasks_per_child=1) as pool:
        large = pool.submit(_child_peak, 200).result()
    assert small < parent - 300, (small, parent)  # not the parent's 400 MiB
    assert large >= small + 150  # and it sees what the child itself touched
    assert float(held[0]) == 1.0
