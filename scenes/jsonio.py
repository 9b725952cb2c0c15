"""JSON read with its nesting bounded: the one reader of the JSON files a user hands nbs-env (floor plans,
glTF headers, checkpoint descriptions).

Python's decoder recurses once per level of ``[`` or ``{``, so a file nested some thousand levels deep
ends in a ``RecursionError`` (and any code that walks the document after it, a schema validator, our
own checks, recurses as deep). :func:`read_json` measures the nesting first, outside strings, and
refuses a document nested deeper than :data:`MAX_JSON_DEPTH` with a :class:`JSONNestingError`, a
``json.JSONDecodeError`` that gives the line and column, so every caller's handling of bad JSON takes it
as it is. This module holds no building: the policies, which must not read ground truth, may use it.
"""

from __future__ import annotations

import json
import re
from typing import Any

import numpy as np

__all__ = ["MAX_JSON_DEPTH", "JSONNestingError", "read_json"]

#: Deepest nesting of arrays and objects read. A floor plan nests 4 levels (plan, rooms, room, polygon,
#: point), a glTF header about 5, a checkpoint description 3: 64 leaves room for any honest document and stays
#: far below Python's recursion limit (1000).
MAX_JSON_DEPTH = 64

# A JSON string, escapes included; brackets inside strings do not nest.
_STRING = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)
_OPEN = (ord("["), ord("{"))
_CLOSE = (ord("]"), ord("}"))


class JSONNestingError(json.JSONDecodeError):
    """A JSON document nested deeper than the reader's bound; ``pos`` is where it first goes deeper."""


def read_json(text: str, *, max_depth: int = MAX_JSON_DEPTH, **kwargs: Any) -> Any:
    """``json.loads(text, **kwargs)``, refusing documents nested deeper than ``max_depth`` before decoding.

    Raises
    ------
    JSONNestingError
        The document is nested deeper than ``max_depth`` (a ``json.JSONDecodeError``).
    json.JSONDecodeError
        Invalid JSON, as ``json.loads`` raises it, or an integer too long to convert.
    """
    # Strings are blanked out keeping their length, so positions stay those of the text.
    masked = _STRING.sub(lambda m: " " * len(m.group()), text)
    codes = np.frombuffer(masked.encode("utf-32-le", errors="surrogatepass"), dtype="<u4")
    brackets = np.flatnonzero(np.isin(codes, _OPEN + _CLOSE))
    if len(brackets) > max_depth:  # fewer brackets cannot nest deeper
        depth = np.cumsum(np.where(np.isin(codes[brackets], _OPEN), 1, -1))
        deeper = np.flatnonzero(depth > max_depth)
        if len(deeper):
            raise JSONNestingError(f"nested deeper than {max_depth} levels", text, int(brackets[deeper[0]]))
    try:
        return json.loads(text, **kwargs)
    except ValueError as exc:
        if isinstance(exc, json.JSONDecodeError) or "integer string conversion" not in str(exc):
            raise  # bad JSON, or a caller's own refusal (parse_constant refusing NaN)
        # Python refuses to convert an integer of more than 4,300 digits (a ValueError that is no
        # JSONDecodeError): a number no honest document holds, reported as the bad JSON it is.
        raise json.JSONDecodeError("a number of more than 4,300 digits", text, 0) from None
