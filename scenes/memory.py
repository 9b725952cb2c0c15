"""The memory this process may still allocate: read from the system, holding no building (the
policies, which must not read ground truth, may use it, as :mod:`scenes.limits` does)."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["CGROUP", "machine_memory", "memory_left"]

_FALLBACK_MEMORY = 16 * 2**30


#: Where a cgroup v2 container's memory limit (``memory.max``) and use (``memory.current``) are read.
CGROUP = Path("/sys/fs/cgroup")


def machine_memory() -> int:
    """Bytes of memory this process may use: the machine's, or its container's limit where lower."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        total = _FALLBACK_MEMORY
    try:  # a cgroup v2 container's limit ("max" where none is set)
        with open(CGROUP / "memory.max") as f:
            limit = f.read().strip()
        if limit.isdigit():
            total = min(total, int(limit))
    except OSError:
        pass
    return total


def memory_left() -> tuple[int, str] | None:
    """The bytes this process may still allocate, and what bounds them: its address-space limit
    (``ulimit -v``) less what it holds, the machine's available memory, or its container's limit
    (cgroup v2) less what the container holds, whichever is least; None where none can be read
    (not Linux)."""
    found: list[tuple[int, str]] = []
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft != resource.RLIM_INFINITY:
            with open("/proc/self/statm") as f:
                held = int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
            found.append((soft - held, "its address-space limit, ulimit -v"))
    except (ImportError, OSError, ValueError):
        pass
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    found.append((int(line.split()[1]) * 1024, "the memory available on this machine"))
    except (OSError, ValueError, IndexError):
        pass
    try:  # a cgroup v2 container's limit less what its processes hold (the machine may have more free)
        with open(CGROUP / "memory.max") as f:
            limit = f.read().strip()
        if limit.isdigit():
            with open(CGROUP / "memory.current") as f:
                found.append((int(limit) - int(f.read().strip()), "its container's memory limit"))
    except (OSError, ValueError):
        pass
    return min(found) if found else None
