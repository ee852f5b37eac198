"""The allocator tuning the renderer relies on: freed wavefront arrays are reused, not refaulted."""

from __future__ import annotations

import platform
import resource

import numpy as np
import pytest

from embree_rt.compiled import retain_freed_memory

GLIBC = platform.libc_ver()[0] == "glibc"


def test_tuning_reports_whether_it_applied_and_is_idempotent() -> None:
    assert retain_freed_memory() is GLIBC
    assert retain_freed_memory() is GLIBC


@pytest.mark.skipif(not GLIBC, reason="mallopt tuning exists on glibc only")
def test_a_freed_wavefront_sized_array_comes_back_without_page_faults() -> None:
    retain_freed_memory()
    pages = 3 * (1 << 18) * 4 // 4096  # one (3, 2^18) float32 array: 768 pages
    np.ones((3, 1 << 18), np.float32).sum()  # the heap grows once
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(20):
        np.ones((3, 1 << 18), np.float32).sum()  # touch every page, then free
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
    # Untuned, glibc maps and unmaps such arrays: 1526 faults measured for this loop.
    assert faults < pages, faults
