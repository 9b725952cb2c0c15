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

import errno
import json
import os
import re
import stat
from typing import Any

import numpy as np

__all__ = [
    "MAX_JSON_BYTES",
    "MAX_JSON_DEPTH",
    "JSONDuplicateKeyError",
    "JSONNestingError",
    "JSONNumberError",
    "JSONSizeError",
    "read_json",
    "read_json_file",
]

#: Deepest nesting of arrays and objects read. A floor plan nests 4 levels (plan, rooms, room, polygon,
#: point), a glTF header about 5, a checkpoint description 3: 64 leaves room for any honest document and stays
#: far below Python's recursion limit (1000).
MAX_JSON_DEPTH = 64
#: The largest JSON file read (plans, checkpoint and training-state descriptions, result records): the
#: largest of them, a floor plan of the largest storey, takes a few megabytes. Read whole and decoded,
#: a file takes several times its size in memory: a 1.5 GB file once ended in a MemoryError.
MAX_JSON_BYTES = 64 << 20

# A JSON string, escapes included; brackets inside strings do not nest. A string never closed runs to
# the end (the second branch): without it the search tried every later quote as a string's start and
# scanned to the end from each, quadratic in the text (80 KB of \" took 14 s).
_STRING = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"|"[\s\S]*', re.DOTALL)
_OPEN = (ord("["), ord("{"))
_CLOSE = (ord("]"), ord("}"))


class JSONNestingError(json.JSONDecodeError):
    """A JSON document nested deeper than the reader's bound; ``pos`` is where it first goes deeper."""


class JSONSizeError(json.JSONDecodeError):
    """A JSON file larger than the reader's bound, refused before it is read (a ``json.JSONDecodeError``,
    so that every caller's handling of bad JSON takes it; its message has no line and column)."""

    def __init__(self, msg: str) -> None:
        super().__init__(msg, "", 0)
        self.args = (msg,)

    def __str__(self) -> str:
        return str(self.msg)


class JSONNumberError(json.JSONDecodeError):
    """An integer beyond a float's range (JSON sets no bound; every number nbs-env reads is used as a float)."""


class JSONDuplicateKeyError(JSONSizeError):
    """A JSON object that names one key twice. The JSON standard leaves such a document's meaning open
    and Python keeps the last value, so a plan or a glTF header edited by hand would be read as what
    its author did not see first; refused instead, naming the key (no line and column: the decoder's
    hook is not told where it is)."""


class _RepeatedKeyError(ValueError):
    pass


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    document = dict(pairs)
    if len(document) != len(pairs):
        seen: set[str] = set()
        for key, _ in pairs:
            if key in seen:
                raise _RepeatedKeyError(key)
            seen.add(key)
    return document


class _HugeIntegerError(ValueError):
    """An integer literal no float can hold (every number nbs-env reads is used as one)."""


def _integer(literal: str) -> int:
    # JSON integers have no bound, and float(10**400) raises OverflowError wherever a setting, a
    # coordinate or a figure is used as a float; refused here, with its place, for every reader.
    value = int(literal)
    if len(literal) > 300:
        try:
            float(value)
        except OverflowError:
            raise _HugeIntegerError(literal) from None
    return value


def json_text(value: Any, limit: int = 60) -> str:
    """``value`` for a message, spelt as JSON spells it (``true``, ``null``, ``[1, 2]``, ``"text"``):
    the values a message names were read from JSON, and Python's spelling (``True``, ``None``) is not
    what the user's file says. Bounded to ``limit`` characters before it is made (a record may hold a
    huge string, list or number); NaN and Infinity as JSON5 and ``--set`` spell them; what JSON
    cannot spell (a numpy array) as Python does.
    """
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 3000:
        return f"an integer of about {int(value.bit_length() * 0.30103):,} digits"
    if isinstance(value, str):
        value = value[: limit + 1]
    elif isinstance(value, (list, tuple)):
        value = list(value[: limit + 1])
    elif isinstance(value, dict):
        value = dict(list(value.items())[: limit + 1])
    try:
        text = json.dumps(value, ensure_ascii=False)  # NaN and Infinity as a --set value spells them
    except (TypeError, ValueError, RecursionError):
        text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def read_json_file(path: str | os.PathLike[str], *, max_bytes: int = MAX_JSON_BYTES, **kwargs: Any) -> Any:
    """:func:`read_json` of a UTF-8 file, its size checked before it is read.

    Raises
    ------
    JSONSizeError
        The file holds more than ``max_bytes``.
    OSError
        The file cannot be read, or is not a regular file.
    UnicodeDecodeError
        It is not UTF-8.
    json.JSONDecodeError
        As :func:`read_json`.
    """
    status = os.stat(path)
    if not stat.S_ISREG(status.st_mode):  # a fifo would block the read for ever, a device not end
        raise OSError(errno.EINVAL, "not a regular file (a fifo, a device or a folder)", os.fspath(path))
    size = status.st_size
    if size > max_bytes:
        raise JSONSizeError(
            f"a file of {size:,} bytes, more than the {max_bytes:,} a JSON file of nbs-env may hold "
            "(is it the file you meant?)"
        )
    # RFC 8259 lets a parser ignore a byte-order mark; editors on Windows write one.
    with open(path, encoding="utf-8-sig") as f:
        text = f.read(max_bytes + 1)  # a file that grows (or a /proc file that claims 0 bytes) stops here
    if len(text) > max_bytes:
        raise JSONSizeError(f"a file of more than {max_bytes:,} bytes, the most a JSON file of nbs-env may hold")
    return read_json(text, **kwargs)


def read_json(text: str, *, max_depth: int = MAX_JSON_DEPTH, **kwargs: Any) -> Any:
    """``json.loads(text, **kwargs)``, refusing documents nested deeper than ``max_depth`` before decoding.

    Unless the caller passes its own ``object_pairs_hook``, an object that names a key twice is refused.

    Raises
    ------
    JSONNestingError
        The document is nested deeper than ``max_depth`` (a ``json.JSONDecodeError``).
    JSONDuplicateKeyError
        An object names a key twice (a ``json.JSONDecodeError``).
    json.JSONDecodeError
        Invalid JSON, as ``json.loads`` raises it, or an integer beyond a float's range.
    """
    # Strings are blanked out keeping their length, so positions stay those of the text. Brackets are
    # ASCII, so the UTF-8 bytes find them at a byte a character (UTF-32 took four).
    masked = _STRING.sub(lambda m: " " * len(m.group()), text).encode("utf-8", errors="surrogatepass")
    codes = np.frombuffer(masked, dtype=np.uint8)
    brackets = np.flatnonzero(np.isin(codes, _OPEN + _CLOSE))
    if len(brackets) > max_depth:  # fewer brackets cannot nest deeper
        depth = np.cumsum(np.where(np.isin(codes[brackets], _OPEN), 1, -1))
        deeper = np.flatnonzero(depth > max_depth)
        if len(deeper):
            at = len(masked[: int(brackets[deeper[0]])].decode("utf-8", errors="surrogatepass"))  # in characters
            raise JSONNestingError(f"nested deeper than {max_depth} levels", text, at)
    del masked, codes, brackets
    kwargs.setdefault("object_pairs_hook", _unique_keys)
    kwargs.setdefault("parse_int", _integer)
    try:
        return json.loads(text, **kwargs)
    except _RepeatedKeyError as exc:
        raise JSONDuplicateKeyError(f"the key {exc.args[0][:80]!r} appears twice in one object") from None
    except _HugeIntegerError as exc:
        literal = exc.args[0]
        raise JSONNumberError(
            f"an integer of {len(literal.lstrip('-')):,} digits, beyond the range of any number nbs-env reads",
            text,
            max(text.find(literal), 0),
        ) from None
    except ValueError as exc:
        if isinstance(exc, json.JSONDecodeError) or "integer string conversion" not in str(exc):
            raise  # bad JSON, or a caller's own refusal (parse_constant refusing NaN)
        # Python refuses to convert an integer of more than 4,300 digits (a ValueError that is no
        # JSONDecodeError): a number no honest document holds, reported as the bad JSON it is.
        masked = _STRING.sub(lambda m: " " * len(m.group()), text)  # a string of digits is no number
        found = re.search(r"-?[0-9]{4301,}", masked)
        raise JSONNumberError("a number of more than 4,300 digits", text, found.start() if found else 0) from None
