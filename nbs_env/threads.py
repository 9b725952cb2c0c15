"""The process's cores for compiled kernels: their work split over Python threads.

The kernels are compiled with ``nogil=True``, so threads run their chunks side by side. Each chunk
is computed exactly as in the whole (rows of sensors, points), so the split changes the time and
nothing else. The number of threads is the cores the process may use (its CPU affinity), or
``NBS_THREADS`` when set: a training run with one env per core sets it to 1.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

__all__ = ["beside", "cores", "split"]

_POOL: ThreadPoolExecutor | None = None
_POOL_SIZE = 0
_BESIDE: ThreadPoolExecutor | None = None


def _forget_pools() -> None:
    """In a child made by ``fork``: the pools' threads were not copied, so work handed to them would
    wait for ever (gymnasium's ``AsyncVectorEnv`` forked after an env had stepped in the parent hung
    at its first reset). The child starts its own pools when it first needs them."""
    global _POOL, _POOL_SIZE, _BESIDE
    _POOL, _POOL_SIZE, _BESIDE = None, 0, None


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pools)


#: ``NBS_THREADS`` may ask for at most this many threads per core the process may use: more only
#: share the same cores, and each takes a stack (10⁵ threads crashed the process).
THREADS_PER_CORE = 4


def _available() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def cores() -> int:
    """Threads for the kernels: ``NBS_THREADS`` when set, else the cores the process may use.

    Raises
    ------
    ValueError
        ``NBS_THREADS`` is not a whole number within 1 .. :data:`THREADS_PER_CORE` × the cores.
    """
    value = os.environ.get("NBS_THREADS")
    available = _available()
    if value:
        most = THREADS_PER_CORE * available
        try:
            n = int(value.strip()) if len(value) <= 20 else -1
        except ValueError:
            n = -1
        if not 1 <= n <= most:
            shown = value if len(value) <= 40 else value[:40] + "…"
            raise ValueError(
                f"NBS_THREADS must be a whole number of threads within 1..{most} ({THREADS_PER_CORE} per core "
                f"of the {available} this process may use), got {shown!r}"
            )
        return n
    return available


def split(
    work: Callable[[slice], Any], rows: int, cost: int, least: int = 100_000, interleave: bool = True
) -> Sequence[Any]:
    """``work(slice)`` for ``n`` slices of ``rows`` rows, run on ``n`` threads.

    ``n`` is :func:`cores`, fewer when ``cost`` (the work's size in the kernel's inner steps) is
    below ``least`` a thread: below that, starting threads costs more than it saves. The slices are
    interleaved (``k::n``), so that rows whose cost grows along the array (far sensors, a room's
    end) share out evenly, or with ``interleave=False`` contiguous runs (views without copies).
    Returns the results in the order of the slices.
    """
    n = min(cores(), rows, max(1, cost // max(least, 1)))
    if n <= 1:
        return [work(slice(0, rows, 1))]
    if not interleave:
        bounds = [rows * k // n for k in range(n + 1)]
        parts = [slice(bounds[k], bounds[k + 1], 1) for k in range(n)]
    global _POOL, _POOL_SIZE
    if _POOL is None or n > _POOL_SIZE:
        _POOL, _POOL_SIZE = ThreadPoolExecutor(max_workers=n, thread_name_prefix="nbs-kernel"), n
    return list(_POOL.map(work, parts if not interleave else [slice(k, None, n) for k in range(n)]))


def beside(work: Callable[[], Any]) -> Future:
    """``work()`` on a thread of its own while the caller goes on, when the process has more than
    one core (else at once, on the caller's); ``.result()`` of the returned future waits for it and
    raises what it raised. For work that releases the GIL beside work that does too (numpy's
    random fills beside Embree's cast)."""
    global _BESIDE
    if cores() <= 1:
        done: Future = Future()
        try:
            done.set_result(work())
        except Exception as exc:  # handed to the caller through .result(), as a thread would
            done.set_exception(exc)
        return done
    if _BESIDE is None:
        _BESIDE = ThreadPoolExecutor(max_workers=1, thread_name_prefix="nbs-beside")
    return _BESIDE.submit(work)
