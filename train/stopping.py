"""Ctrl-C and SIGTERM during ``nbs scan`` and ``nbs compare``: stop at the next step, keep what is done.

The design of ``nbs train``'s (:mod:`train.ppo`): the signal handler only sets a flag, and the work
looks at it between its steps, so that a signal never lands in the middle of a write. ``nbs scan``
then writes the report of the scans taken, ``nbs compare`` stops its workers and keeps the runs
already recorded; both exit with ``128 + the signal`` (130 for SIGINT, 143 for SIGTERM), as a shell
reports a process the signal ended. A second signal does not wait for the next step: it raises
:class:`KeyboardInterrupt` at once.
"""

from __future__ import annotations

import signal
import threading
from types import FrameType
from typing import Any

__all__ = ["STOP_SIGNALS", "StopRequest", "exit_code", "ignore_interrupts"]

#: The signals a :class:`StopRequest` catches.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def exit_code(sig: int) -> int:
    """The exit code of a command stopped by ``sig``: 128 + its number, as shells report it."""
    return 128 + int(sig)


def ignore_interrupts() -> None:
    """In a worker process: Ctrl-C, sent by the terminal to the whole process group, is the parent
    process's to handle (it keeps the finished work, then ends the workers), not a worker's to die
    of with a traceback."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


class StopRequest:
    """SIGINT and SIGTERM, while in this context, ask the work to stop at its next step.

    Calling it says whether a stop was asked. Outside the main thread (where Python delivers
    signals) it installs nothing and never asks. The previous handlers come back on exit.

    Attributes
    ----------
    signal : int or None
        The first signal received, or None.
    """

    def __init__(self) -> None:
        self.signal: int | None = None
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> StopRequest:
        if threading.current_thread() is threading.main_thread():
            for sig in STOP_SIGNALS:
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()

    def __call__(self) -> bool:
        return self.signal is not None

    @property
    def name(self) -> str:
        """The signal's name (``"SIGINT"``), or ``""``."""
        return "" if self.signal is None else signal.Signals(self.signal).name

    def _handle(self, sig: int, frame: FrameType | None) -> None:
        if self.signal is not None:
            # Asked twice: the user will not wait for the step to end.
            raise KeyboardInterrupt
        self.signal = sig
