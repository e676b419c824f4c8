"""The default memory budget of an analysis, and the CPUs it may use (cheap to import: the command
line reads them for --help)."""

from __future__ import annotations

import contextlib
import functools
import os
import sys

__all__ = ["cpus", "default_max_bytes", "lower_priority", "resident_bytes", "room"]


@functools.cache
def default_max_bytes() -> int:
    """The default byte budget of one analysis: half the physical memory or 4 GiB, whichever is
    smaller (4 GiB when the physical memory cannot be read). Read once per process."""
    try:
        total = int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 4 << 30
    return int(min(total // 2, 4 << 30))


def resident_bytes() -> int:
    """The bytes this process holds in physical memory now (its resident set, Linux's
    ``/proc/self/statm``); 0 where that cannot be read."""
    try:
        with open("/proc/self/statm", "rb") as fh:
            return int(fh.read().split()[1]) * int(os.sysconf("SC_PAGE_SIZE"))
    except (OSError, ValueError, IndexError, AttributeError):
        return 0


def room(max_bytes: int) -> int:
    """What a part of an analysis whose data may fill its budget ``max_bytes`` (the symbolic
    engine) may take, bytes: ``max_bytes``, less what the process already holds
    (:func:`resident_bytes`: the interpreter, the net, the linear programs' leftovers) where the
    two together would pass the larger of ``max_bytes`` and :func:`default_max_bytes`. So under the
    default budget what the process holds counts against it (AirplaneLD-PT-2000: 0.7 to 0.9 GiB
    held when its decision diagram starts, whose peak was 3.4 to 4.1 GiB with the whole 4 GiB
    given), and a small budget asked for still bounds the data alone. Never below 0."""
    ceiling = max(max_bytes, default_max_bytes())
    return max(0, min(max_bytes, ceiling - resident_bytes()))


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
