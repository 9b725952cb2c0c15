"""The references of a STEP file (ISO 10303-21, the text form of IFC), checked before a reader follows them.

ifcopenshell follows an entity's references recursively, in C++ (the geometry engine: booleans,
mapped items, curves) and in Python (placements): a reference that leads back to where it started
made it loop without end, deaf to signals, or overflow the C stack (a segmentation fault); a chain of
20,000 placements ended in a ``RecursionError``. Real files are shallow: the deepest chain in the
corpus's IFC files is :data:`CORPUS_DEEPEST` references. This module reads the instance lines with
the standard library and refuses a file whose references form a cycle or a chain deeper than
:data:`MAX_REFERENCE_DEPTH`, naming the entities.
"""

from __future__ import annotations

import re
import warnings

from scenes.errors import IfcError

__all__ = [
    "CORPUS_DEEPEST",
    "MAX_REFERENCE_DEPTH",
    "DanglingReferencesWarning",
    "check_chains",
    "check_references",
    "deepest_chains",
    "reference_graph",
]

#: The deepest chain of references in the corpus's IFC files (FZK-Haus, the authored houses, the
#: buildingSMART samples): measured by :func:`reference_graph`.
CORPUS_DEEPEST = 14
#: The most references a chain may hold: ten times the corpus's deepest, and well within the
#: recursion ifcopenshell's Python placement code (two frames a level) has.
MAX_REFERENCE_DEPTH = 160

# Strings ('' escapes a quote) and comments may hold anything, '#12' and ';' included.
# A string or comment never closed runs to the end (the last two branches): without them each later quote
# was tried as a start and scanned to the end, quadratic in the file.
_STRINGS_AND_COMMENTS = re.compile(rb"'(?:[^']|'')*'|/\*.*?\*/|'[\s\S]*|/\*[\s\S]*", re.DOTALL)


def _blank(data: bytes) -> bytes:
    """``data`` with every string emptied and every comment a space (a comment ends no statement and
    starts none)."""
    return _STRINGS_AND_COMMENTS.sub(lambda m: b" " if m.group(0).startswith(b"/*") else b"''", data)


# ifcopenshell reads "# 12" and "#\n12" as #12: so are they read here.
_INSTANCE = re.compile(rb"\s*#\s*(\d+)\s*=\s*([A-Za-z0-9_]*)")
_REFERENCE = re.compile(rb"#\s*(\d+)")
_BAD_NAME = re.compile(rb"#(?!\s*\d)[^,)\s;]{0,10}")


class DanglingReferencesWarning(UserWarning):
    """References to instances the file does not define: the reader leaves them empty.

    Attributes
    ----------
    source : str
    count : int
        How many references dangle.
    """

    def __init__(self, source: str, count: int, examples: str) -> None:
        self.source, self.count = source, count
        super().__init__(
            f"{source}: {count:,} reference(s) name instances the file does not define ({examples}"
            f"{', ...' if count > 3 else ''}); what they held is missing: is the file complete?"
        )


def reference_graph(data: bytes, *, blank: bool = True) -> tuple[dict[int, list[int]], dict[int, str], list[int]]:
    """The instances of a STEP file's DATA sections and the instances each refers to.

    Parameters
    ----------
    data : bytes
        The file.
    blank : bool
        Empty its strings and comments first (False: the caller has).

    Returns
    -------
    refers : dict of int to list of int
        Each instance's id and the ids its attributes name, in order (ids no instance carries
        included: the reader says what is missing).
    kinds : dict of int to str
        Each instance's entity name as written (``IFCWALL``), for messages.
    repeated : list of int
        Ids defined more than once (the last definition is in ``refers``).
    """
    text = _blank(data) if blank else data
    refers: dict[int, list[int]] = {}
    kinds: dict[int, str] = {}
    repeated: list[int] = []
    for statement in text.split(b";"):
        head = _INSTANCE.match(statement)
        if head is None:
            continue  # the header section, DATA; ENDSEC; and the end marker
        ident = int(head.group(1))
        if ident in refers:
            repeated.append(ident)
        kinds[ident] = head.group(2).decode("ascii", errors="replace")
        refers[ident] = [int(r) for r in _REFERENCE.findall(statement, head.end())]
    return refers, kinds, repeated


def deepest_chains(refers: dict[int, list[int]]) -> tuple[dict[int, int], list[int] | None]:
    """The longest chain of references from each instance, or the first cycle met.

    Returns
    -------
    depth : dict of int to int
        References in the longest chain that starts at each instance (0: it refers to nothing).
    cycle : list of int or None
        Ids of a cycle, in order (the first id again at its end), or None.
    """
    depth: dict[int, int] = {}
    on_path: dict[int, int] = {}  # id: its place on the path being walked
    for root in refers:
        if root in depth:
            continue
        path = [root]
        children = [iter(refers[root])]
        on_path[root] = 0
        while path:
            node = path[-1]
            for child in children[-1]:
                if child in depth or child not in refers:
                    continue
                if child in on_path:
                    return depth, [*path[on_path[child] :], child]
                on_path[child] = len(path)
                path.append(child)
                children.append(iter(refers[child]))
                break
            else:
                depth[node] = max((depth.get(c, -1) + 1 for c in refers[node] if c in refers), default=0)
                del on_path[node]
                path.pop()
                children.pop()
    return depth, None


def check_references(source: str, data: bytes) -> None:
    """Refuse a STEP file whose references form a cycle or a chain deeper than :data:`MAX_REFERENCE_DEPTH`.

    Raises
    ------
    IfcError
        Naming the cycle's instances and entities, or the deepest chain's first instance and length.
    """
    text = _blank(data)
    refers, kinds, repeated = reference_graph(text, blank=False)
    if repeated:
        raise IfcError(source, f"instance #{repeated[0]} is defined twice: a reader keeps one and drops the other")
    odd = _BAD_NAME.search(text)
    if odd is not None:
        shown = odd.group(0).decode("ascii", errors="replace")
        raise IfcError(source, f"{shown!r} names no instance (an instance is # and digits)")
    dangling = [(i, r) for i, names in refers.items() for r in names if r not in refers]
    if dangling:
        # Real exporters leave a few (a window style's missing property sets); a file cut short and
        # given its end marker leaves many, and loses what the missing part held.
        pairs = ", ".join(f"#{i} -> #{r}" for i, r in dangling[:3])
        warnings.warn(DanglingReferencesWarning(source, len(dangling), pairs), stacklevel=3)
    check_chains(source, refers, kinds, "references", MAX_REFERENCE_DEPTH, CORPUS_DEEPEST)


def check_chains(
    source: str, refers: dict[int, list[int]], kinds: dict[int, str], what: str, most: int, real: int
) -> None:
    """Refuse a graph of a file's instances with a cycle or a chain of more than ``most`` edges.

    Parameters
    ----------
    source : str
        The file, for messages.
    refers : dict of int to list of int
        Each instance's id and the ids it leads to.
    kinds : dict of int to str
        Entity names by id, for messages.
    what : str
        What the edges are, for messages ("references", "decompositions").
    most, real : int
        The bound, and the deepest chain of real files (said in the message).

    Raises
    ------
    IfcError
    """
    depth, cycle = deepest_chains(refers)
    if cycle is not None:
        shown = " -> ".join(f"#{i} ({kinds.get(i, '?')})" for i in cycle[:6])
        more = f" ... ({len(cycle) - 1} instances)" if len(cycle) > 6 else ""
        raise IfcError(source, f"the file's {what} form a cycle: {shown}{more}; a reader would follow it forever")
    if depth:
        start = max(depth, key=depth.__getitem__)
        if depth[start] > most:
            raise IfcError(
                source,
                f"#{start} ({kinds.get(start, '?')}) starts a chain of {depth[start]:,} {what}, at most {most} (real "
                f"files hold {real} at most): a reader follows them recursively",
            )
