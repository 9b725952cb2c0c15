"""The public API's docstrings: every function and method a user reaches through ``nbs_env.__all__`` and
``policies.__all__`` says, in numpy style, what it takes (``Parameters``) and what it gives back
(``Returns``), so that ``help()`` and the API reference answer without reading the code."""

from __future__ import annotations

import inspect
import re
import sys
from collections.abc import Callable, Iterator

import nbs_env
import policies

PACKAGES = (nbs_env, policies)


def _section(doc: str, *names: str) -> bool:
    """Whether ``doc`` has a numpy section headed by one of ``names`` (the name, then a dashed line)."""
    return any(re.search(rf"^[ \t]*{name}[ \t]*\n[ \t]*-{{3,}}[ \t]*$", doc, re.MULTILINE) for name in names)


def _own_doc(obj: object) -> str:
    """``obj``'s own docstring, dedented (not one inherited from a base class)."""
    doc = getattr(obj, "__doc__", None)
    return inspect.cleandoc(doc) if isinstance(doc, str) else ""


def _takes_parameters(fn: Callable) -> bool:
    return any(name not in ("self", "cls") for name in inspect.signature(fn).parameters)


def _defined_in(fn: Callable, cls: type, name: str) -> bool:
    """Whether ``fn`` was written in ``cls``'s body as ``name`` (dataclass-made ``__init__`` included), not
    assigned from elsewhere (a Protocol's placeholder ``__init__``)."""
    return getattr(fn, "__qualname__", None) == f"{cls.__qualname__}.{name}"


def _init_of(cls: type) -> Callable | None:
    """The ``__init__`` that constructs ``cls``, its own or a base class's; None where that is the
    standard library's (``object``'s, an Enum's, a Protocol's placeholder)."""
    for klass in cls.__mro__:
        fn = vars(klass).get("__init__")
        if inspect.isfunction(fn) and _defined_in(fn, klass, "__init__"):
            return None if klass.__module__.split(".")[0] in sys.stdlib_module_names else fn
    return None


def _public_api() -> Iterator[tuple[str, object]]:
    """(dotted name, object) of every exported function and class, exceptions and constants left out."""
    for package in PACKAGES:
        for name in package.__all__:
            if name.startswith("_"):
                continue
            obj = getattr(package, name)
            if inspect.isclass(obj) and issubclass(obj, BaseException):
                continue
            if inspect.isclass(obj) or inspect.isfunction(obj):
                yield f"{package.__name__}.{name}", obj


def doc_gaps(qualname: str, fn: Callable) -> list[str]:
    """What the docstring of the function or method ``fn`` lacks, each as ``"qualname: what"``."""
    doc = _own_doc(fn)
    if not doc:
        return [f"{qualname}: no docstring"]
    gaps = []
    if _takes_parameters(fn) and not _section(doc, "Parameters"):
        gaps.append(f"{qualname}: no Parameters section")
    returns = inspect.signature(fn).return_annotation
    if returns not in (inspect.Signature.empty, None, "None") and not _section(doc, "Returns", "Yields"):
        gaps.append(f"{qualname}: no Returns section")
    return gaps


def class_gaps(qualname: str, cls: type) -> list[str]:
    """What the docstrings of the class ``cls`` and of the public methods defined in it lack."""
    gaps = []
    init = _init_of(cls)
    if init is not None and _takes_parameters(init) and not _section(_own_doc(cls), "Parameters", "Attributes"):
        gaps.append(f"{qualname}: its __init__ takes parameters; the class docstring has no Parameters section")
    for name, member in vars(cls).items():
        if name.startswith("_"):
            continue
        fn = member.__func__ if isinstance(member, (staticmethod, classmethod)) else member
        if inspect.isfunction(fn) and _defined_in(fn, cls, name):
            gaps += doc_gaps(f"{qualname}.{name}", fn)
    return gaps


def api_gaps() -> list[str]:
    gaps = []
    for qualname, obj in _public_api():
        gaps += class_gaps(qualname, obj) if inspect.isclass(obj) else doc_gaps(qualname, obj)
    return gaps


def test_public_api_is_documented():
    """Every exported function and public method has a docstring, with a ``Parameters`` section when it
    takes parameters and a ``Returns`` (or ``Yields``) section when it is annotated to return something;
    a class constructed with parameters names them (``Parameters`` or ``Attributes``)."""
    gaps = api_gaps()
    assert not gaps, f"{len(gaps)} docstring gaps in the public API:\n" + "\n".join(gaps)


def test_the_walk_reaches_the_api():
    """The walk sees the env's and the policies' methods, including lazily loaded names."""
    names = {qualname for qualname, _ in _public_api()}
    assert {"nbs_env.NBSEnv", "nbs_env.make_config", "policies.make_policy", "policies.LearnedPolicy"} <= names
    assert "nbs_env.NBSError" not in names  # exceptions are left out


def test_checker_catches_gaps():
    """The checker flags a missing docstring, a missing section and a class that hides its parameters,
    and passes a documented function."""

    def documented(x: int) -> int:
        """Twice ``x``.

        Parameters
        ----------
        x : int

        Returns
        -------
        int
        """
        return 2 * x

    def bare(x: int) -> int:
        return x

    def mentions_only(x: int) -> int:
        """Parameters and Returns named in prose are not sections."""
        return x

    class Undocumented:
        """Made with a parameter it does not name."""

        def __init__(self, size: int) -> None:
            self.size = size

        def grow(self, by: int) -> None:
            """Grow."""

    assert doc_gaps("documented", documented) == []
    assert doc_gaps("bare", bare) == ["bare: no docstring"]
    assert doc_gaps("mentions_only", mentions_only) == [
        "mentions_only: no Parameters section",
        "mentions_only: no Returns section",
    ]
    assert class_gaps("Undocumented", Undocumented) == [
        "Undocumented: its __init__ takes parameters; the class docstring has no Parameters section",
        "Undocumented.grow: no Parameters section",
    ]
