"""Wall time and peak-memory measurement."""

from __future__ import annotations

import math
import mmap
import time

import pytest

from fkn_bench.harness.profiling import measure, peak_rss_supported


def test_wall_time() -> None:
    with measure(memory=False) as m:
        time.sleep(0.02)
    assert 0.015 < m.seconds < 1.0 and math.isnan(m.peak_memory_mib)


@pytest.mark.skipif(not peak_rss_supported(), reason="needs Linux /proc peak-RSS reset")
def test_peak_memory_sees_a_transient_allocation() -> None:
    size = 40 * 2**20
    with measure() as m:
        block = mmap.mmap(-1, size)  # fresh anonymous pages: the allocator cannot reuse resident memory
        block.write(b"x" * size)  # touch every page
        block.close()
    assert m.peak_memory_mib > 30
    with measure() as small:
        pass
    assert small.peak_memory_mib < 30
