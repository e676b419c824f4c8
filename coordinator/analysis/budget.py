"""The default memory budget of an analysis, and the CPUs it may use (cheap to import: the command
line reads them for --help)."""

from __future__ import annotations

import contextlib
import functools
import os
import sys

__all__ = ["cpus", "default_max_bytes", "lower_priority"]


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


def lower_priority(tid: int, by: int) -> None:
    """Lower the scheduling priority of thread ``tid`` (a native thread id of this process,
    ``threading.get_native_id()``) by ``by`` nice steps, to at most 19. Linux only, where a thread
    is a scheduling entity of its own; elsewhere, or when refused, nothing changes. A priority
    once lowered is not raised again: an unprivileged process may not."""
    if not sys.platform.startswith("linux"):
        return
    with contextlib.suppress(OSError):
        os.setpriority(os.PRIO_PROCESS, tid, min(19, os.getpriority(os.PRIO_PROCESS, tid) + by))
