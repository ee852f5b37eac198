"""How much memory the machine has free now, and sizes said in GB: what ``budget`` and the
readers that refuse an oversized header before allocating both ask."""

from __future__ import annotations

import os
from pathlib import Path


def format_bytes(size: float) -> str:
    """``size`` bytes as GB with three significant digits (``"0.512 GB"``, ``"800 GB"``)."""
    gigabytes = size / 1e9
    return f"{gigabytes:,.0f} GB" if gigabytes >= 100 else f"{gigabytes:.3g} GB"


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation now: ``MemAvailable`` from /proc/meminfo
    (what the kernel can hand out without swapping), else the free physical pages, else None
    (unknown: nothing is refused)."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, OSError, ValueError):
        return None
