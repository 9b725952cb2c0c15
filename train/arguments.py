"""Values the ``nbs`` commands read from their command lines, parsed in one place."""

from __future__ import annotations

import tempfile
from pathlib import Path

__all__ = ["output_folder_problem", "parse_range"]


def parse_range(text: str) -> tuple[int, int]:
    """``"A-B"`` → ``(A, B)`` and ``"A"`` → ``(A, A)``, for integers 0 <= A <= B.

    Raises
    ------
    ValueError
        Anything else, with a message that quotes ``text``.
    """
    lo, sep, hi = str(text).strip().partition("-")
    try:
        a = int(lo)
        b = int(hi) if sep else a
    except ValueError:
        raise ValueError(f"expected N or A-B with integers 0 <= A <= B, got {text!r}") from None
    if a < 0 or b < a:
        raise ValueError(f"expected N or A-B with integers 0 <= A <= B, got {text!r}")
    return a, b


def output_folder_problem(path: str | Path) -> str | None:
    """Why no report could be written into the folder ``path`` (None when it can), found before any
    work starts and without creating it: it exists and is no folder, or the nearest folder that
    exists (itself, or the one it would be made in) takes no file. A file is really written there and
    removed: permission bits say nothing for root or on read-only mounts."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        return "exists and is not a folder"
    here = path
    while not here.exists():
        here = here.parent
    if not here.is_dir():
        return f"cannot create it: {here} is not a folder"
    try:
        with tempfile.TemporaryFile(dir=here):
            pass
    except OSError as exc:
        return f"cannot write in {here} ({exc.strerror or exc})"
    return None
