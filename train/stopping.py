"""Ctrl-C, SIGTERM and SIGHUP during ``nbs scan``, ``nbs compare`` and ``nbs train``: stop at the
next step, keep what is done.

The signal handler only sets a flag, and the work looks at it between its steps, so that a signal
never lands in the middle of a write. ``nbs scan`` then writes the report of the scans taken,
``nbs compare`` stops its workers and keeps the runs already recorded, ``nbs train`` saves its
state; each exits with ``128 + the signal`` (130 for SIGINT, 143 for SIGTERM, 129 for SIGHUP: the
terminal or the SSH session closed), as a shell reports a process the signal ended. A second
signal does not wait for the next step: it raises :class:`KeyboardInterrupt` at once, except while
the work writes what it keeps (:meth:`StopRequest.hold`). SIGQUIT keeps its meaning, a debugging
stop with no clean-up.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from types import FrameType
from typing import Any

__all__ = [
    "STOP_SIGNALS",
    "StopRequest",
    "defer_signals",
    "exit_code",
    "ignore_interrupts",
    "interrupt_on_signals",
    "pending_signal",
    "start_resource_tracker",
    "undefer_signals",
]

#: The signals a :class:`StopRequest` catches.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, *([signal.SIGHUP] if hasattr(signal, "SIGHUP") else []))


def exit_code(sig: int) -> int:
    """The exit code of a command stopped by ``sig``: 128 + its number, as shells report it."""
    return 128 + int(sig)


def ignore_interrupts() -> None:
    """In a worker process: Ctrl-C and a closed terminal's SIGHUP, sent to the whole process group,
    are the parent process's to handle (it keeps the finished work, then ends the workers), not a
    worker's to die of with a traceback. A parent that cannot end them (SIGKILL, the kernel's
    out-of-memory killer) ends them by dying: on Linux each gets SIGTERM then (a killed grid left
    its workers, 0.4 GB each, running on for minutes)."""
    for sig in STOP_SIGNALS:
        if sig != signal.SIGTERM:  # the parent ends its workers with SIGTERM
            signal.signal(sig, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # 1: PR_SET_PDEATHSIG
        if os.getppid() == 1:  # the parent died before the call: no signal would come
            os._exit(1)


def start_resource_tracker() -> None:
    """Start multiprocessing's resource tracker, before a pool of workers does, deaf to SIGHUP.

    The tracker, a process of its own, ignores SIGINT and SIGTERM but not SIGHUP, which a closing
    terminal (and ``timeout -s HUP``) sends to the whole process group: it died, a new one was
    started for the next worker, and that one printed a leak warning and a traceback for each
    semaphore it had never seen. Blocked here while it starts, SIGHUP stays blocked in it (the mask
    is inherited); this process receives a SIGHUP of that moment when it is unblocked.
    """
    if not hasattr(signal, "SIGHUP") or not hasattr(signal, "pthread_sigmask"):
        return
    from multiprocessing import resource_tracker

    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGHUP})
    try:
        resource_tracker.ensure_running()
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGHUP})


#: A signal received while a command was still starting (:func:`defer_signals`), not yet acted on.
_pending: int | None = None
_pending_at = 0.0

#: The same signal again within this many seconds is the same request delivered twice, not a second
#: one: `timeout` and a closing terminal signal the process itself and then its whole group, and
#: Python runs the handler for each when the two fall either side of a bytecode. A person's second
#: Ctrl-C comes later.
DUPLICATE_S = 0.1


def _again(first: int | None, first_at: float, sig: int) -> bool:
    """Whether ``sig`` asks again (``first`` came at ``first_at``), not the same request delivered twice."""
    return first is not None and not (sig == first and time.monotonic() - first_at < DUPLICATE_S)


def _record(sig: int, frame: FrameType | None) -> None:
    global _pending, _pending_at
    if _again(_pending, _pending_at, sig):  # asked twice: do not wait
        raise KeyboardInterrupt
    if _pending is None:
        _pending, _pending_at = sig, time.monotonic()


def defer_signals() -> None:
    """From a command's first line: SIGINT and SIGTERM are recorded, not raised, until a
    :class:`StopRequest` takes them over (it then stops the work at its first step) or the command
    ends (:func:`pending_signal`). While a command imports its libraries a ``KeyboardInterrupt``
    could land inside one that catches every exception around an optional import, and the signal
    would be lost: the command then ran to its end as if never asked to stop."""
    global _pending
    _pending = None
    if threading.current_thread() is threading.main_thread():
        for sig in STOP_SIGNALS:
            signal.signal(sig, _record)


def _interrupt(sig: int, frame: FrameType | None) -> None:
    global _pending, _pending_at
    if _pending is None:
        _pending, _pending_at = sig, time.monotonic()
    raise KeyboardInterrupt


def interrupt_on_signals() -> None:
    """For a command with nothing to keep (``nbs scenes info``, ``show``, ``generate``, whose files are
    written whole or not at all): from here SIGINT and SIGTERM stop it at the next Python line, and
    one recorded while it loaded its libraries does so now. Deferred to its end, a SIGTERM waited out
    a load of minutes. (A call into C++ that does not return, ifcopenshell's geometry, still defers
    it until it does: the loaders refuse the inputs that made one loop.)"""
    if threading.current_thread() is threading.main_thread():
        for sig in STOP_SIGNALS:
            signal.signal(sig, _interrupt)
    if _pending is not None:
        raise KeyboardInterrupt


def undefer_signals() -> None:
    """Python's own handling of SIGINT and SIGTERM again, for a command that waits for Ctrl-C itself
    (``nbs view --web``); a signal recorded meanwhile is raised now as ``KeyboardInterrupt``."""
    if threading.current_thread() is threading.main_thread():
        for sig in STOP_SIGNALS:
            signal.signal(sig, signal.default_int_handler if sig == signal.SIGINT else signal.SIG_DFL)
    if _pending is not None:
        raise KeyboardInterrupt


def pending_signal() -> int | None:
    """The signal :func:`defer_signals` recorded and no :class:`StopRequest` took over, or None."""
    return _pending


class StopRequest:
    """SIGINT and SIGTERM, while in this context, ask the work to stop at its next step.

    Calling it says whether a stop was asked. Outside the main thread (where Python delivers
    signals) it installs nothing and never asks. The previous handlers come back on exit.

    Attributes
    ----------
    signal : int or None
        The first signal received, or None.

    Parameters
    ----------
    escalate_after : float, optional
        Seconds after the first signal at which it is delivered again, as a second one (a
        ``KeyboardInterrupt`` unless the work is holding): for work whose steps may outlast a
        supervisor's grace before SIGKILL (a training step on a large storey took minutes, and the
        run was killed with nothing saved). None: wait for the step, however long.
    """

    def __init__(self, escalate_after: float | None = None) -> None:
        self.signal: int | None = None
        self._previous: dict[int, Any] = {}
        self._holding = False
        self._at = 0.0
        self.escalate_after = escalate_after
        self._timer: threading.Timer | None = None

    def __enter__(self) -> StopRequest:
        global _pending
        if threading.current_thread() is threading.main_thread():
            for sig in STOP_SIGNALS:
                self._previous[sig] = signal.signal(sig, self._handle)
        if _pending is not None:  # asked while the command was starting: stop at the first step
            self.signal, self._at, _pending = _pending, _pending_at, None
            self._escalate(self.signal)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._timer is not None:
            self._timer.cancel()
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()

    def _escalate(self, sig: int) -> None:
        if self.escalate_after is not None and self._timer is None and self._previous:
            self._timer = threading.Timer(self.escalate_after, os.kill, (os.getpid(), sig))
            self._timer.daemon = True
            self._timer.start()

    def __call__(self) -> bool:
        return self.signal is not None

    @property
    def name(self) -> str:
        """The signal's name (``"SIGINT"``), or ``""``."""
        return "" if self.signal is None else signal.Signals(self.signal).name

    @contextlib.contextmanager
    def hold(self) -> Iterator[None]:
        """While in this context, a second signal is not raised either: the work is writing what it
        keeps (a report, a training state), which takes seconds and which a second Ctrl-C would
        leave half-written."""
        self._holding = True
        try:
            yield
        finally:
            self._holding = False

    def _handle(self, sig: int, frame: FrameType | None) -> None:
        if self.signal is not None:
            if self._holding or not _again(self.signal, self._at, sig):
                return
            # Asked twice: the user will not wait for the step to end.
            raise KeyboardInterrupt
        self.signal, self._at = sig, time.monotonic()
        self._escalate(sig)
