"""Values the ``nbs`` commands read from their command lines, parsed in one place."""

from __future__ import annotations

__all__ = ["parse_range"]


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
