"""The default memory budget of an analysis, and the CPUs it may use (cheap to import: the command
line reads them for --help)."""

from __future__ import annotations

import functools
import os

__all__ = ["cpus", "default_max_bytes"]


@functools.cache
def default_max_bytes() -> int:
    """The default byte budget of one analysis: half the physical memory or 4 GiB, whichever is
    smaller (4 GiB when the physical memory cannot be read). Read once per process."""
    try:
        total = int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 4 << 30
    return int(min(total // 2, 4 << 30))


def cpus() -> int:
    """The CPUs this process may run on (its affinity), at least 1: the symbolic engine races two
    variable orders, and the automatic engine runs the explicit search beside it, on two or more."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return os.cpu_count() or 1
