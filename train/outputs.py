"""The output paths of a command, checked before it does any work.

A scan or a grid can run for hours; a path it cannot write, found when it writes, loses that work.
:func:`check_outputs` looks at every output path a command was given, at its start, without
creating anything: a folder (``--out``) must be a folder or not exist yet, in a folder that exists;
a file (``--record``) must not be a folder, nor be typed as one (``gdir/``), and its folder must
exist; each folder it would be written in must take a file (one is created there and removed:
permission bits say nothing for root or on a read-only mount); and what an earlier run left there
(a non-empty folder, an existing file) is refused unless the command was told to replace it. The
message names the flag and the path.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import hashlib
import os
import stat
import tempfile
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

__all__ = [
    "NamedStream",
    "Output",
    "OutputBusyError",
    "OutputError",
    "check_outputs",
    "claimed",
    "odd_entry",
    "output_path",
    "utf8_problem",
]


class OutputError(ValueError):
    """An output path that cannot be written, or holds what an earlier run left; the message says
    which flag, which path and why, on one line."""


class OutputBusyError(OutputError):
    """An output path another command is writing now (:func:`claimed`)."""


@dataclass(frozen=True)
class Output:
    """One output path of a command line.

    Attributes
    ----------
    flag : str
        The option that named it, for the message (``"--out"``).
    path : Path
    kind : {"folder", "file"}
        A folder the command fills (and makes when missing), or one file it writes.
    replace : str or None
        What to pass to write over what an earlier run left there (``"pass --force to overwrite
        it"``), said when it is refused; None: an existing file or non-empty folder is fine.
    example : str
        For a file: a name to suggest when the path is a folder (``"run.rrd"``).
    files : tuple of str
        For a folder: the names the command writes in it (a report's), checked against its inputs.
    others : tuple of (str, str)
        For a folder: names another command's product holds, with what that product is
        (``("table.md", "a comparison")``): a folder holding one is refused, ``--force`` or not,
        since the command would mix its files into it (and replace only its own).
    """

    flag: str
    path: Path
    kind: Literal["folder", "file"] = "folder"
    replace: str | None = None
    example: str = ""
    files: tuple[str, ...] = ()
    others: tuple[tuple[str, str], ...] = ()


#: What each command's folder holds that no other command writes: a scan report, a comparison, a
#: training run (or a checkpoint folder).
SCAN_REPORT = (("scans.e57", "a scan report"), ("metrics.json", "a scan report"))
COMPARISON = (("oracle.json", "a comparison"), ("table.md", "a comparison"), ("runs", "a comparison"))
TRAINING_RUN = (("training_state.json", "a training run"), ("policy.json", "a checkpoint"))


class _FolderLike(type(Path())):  # type: ignore[misc]  # PosixPath or WindowsPath
    """A path typed with a trailing separator (``gdir/``): the user means a folder, which ``Path``
    forgets by dropping the separator. ``given`` is the text as typed, for the message; paths made
    from it (``.parent``, ``/``) do not carry it."""

    given: str | None = None


def output_path(text: str) -> Path:
    """argparse type of an output path: an empty one (``--out ''``) names no file or folder, and
    ``Path('')`` would quietly be the working folder. One that ends with a separator keeps that it
    does (:class:`_FolderLike`): where a file is wanted, :func:`check_outputs` refuses it."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty path names no file or folder")
    if text.endswith(tuple(sep for sep in (os.sep, os.altsep) if sep)):
        path = _FolderLike(text)
        path.given = text
        return path
    return Path(text)


def _shown(path: Path) -> str:
    """``path`` as the user typed it, a trailing separator included."""
    return getattr(path, "given", None) or str(path)


def _write_problem(folder: Path) -> str | None:
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        return f"cannot make a file in {folder} ({exc.strerror or exc})"
    return None


def _parent_problem(path: Path) -> str | None:
    """Why no file or folder can be made at ``path``: its folder is missing, no folder, or takes no file."""
    parent = path.parent
    if not parent.exists():
        return f"its folder {parent} does not exist"
    if not parent.is_dir():
        return f"{parent} is not a folder"
    return _write_problem(parent)


def _problem(output: Output) -> str | None:
    path = output.path
    if path.is_symlink():
        try:
            os.stat(path)
        except FileNotFoundError:  # a link to nothing: a file is made at its target, a folder cannot be
            if output.kind == "folder":
                return f"is a link to {os.readlink(path)}, which does not exist; name a folder"
        except OSError as exc:  # a loop of links
            return f"cannot be used ({exc.strerror or exc})"
    if output.kind == "folder":
        if not path.exists():
            return _parent_problem(path)
        if not path.is_dir():
            return "exists and is not a folder"
        problem = _write_problem(path)
        # --force replaces this command's files, not another's: the two would be mixed.
        held_by_other = next(((n, w) for n, w in output.others if os.path.lexists(path / n)), None)
        if problem is None and held_by_other is not None:
            return f"holds {held_by_other[1]} ({held_by_other[0]}); choose another folder"
        if problem is None and output.replace is not None:
            try:
                held = sorted(p.name + ("/" if p.is_dir() else "") for p in path.iterdir())
            except OSError as exc:
                return f"cannot list it ({exc.strerror or exc})"
            if held:
                shown = ", ".join(held[:4]) + (", ..." if len(held) > 4 else "")
                return f"is not empty (it holds {shown}); {output.replace}, or choose another folder"
        return problem
    if output.kind != "file":
        raise ValueError(f"an output is a folder or a file, got {output.kind!r}")
    if path.is_dir():
        example = f" (e.g. {path / output.example})" if output.example else ""
        return f"is a folder; name a file in it{example}"
    if getattr(path, "given", None):
        # `--out gdir/` would quietly write a file named gdir where the user meant a folder.
        advice = f"name a file in it (e.g. {path / output.example})" if output.example else "name a file"
        return f"ends with a separator, so it names a folder, not a file; {advice}"
    if path.exists() and not path.is_file():
        # Renamed over, a device (/dev/full), a fifo or a socket would be replaced by a plain file.
        return "is not a regular file (a device, a fifo or a socket); name a file"
    if path.is_symlink():  # a link to nothing yet too: the file is made at its target
        target = Path(os.path.realpath(path))
        if target.suffix.lower() != path.suffix.lower():
            # Written at the link's target: `plan.json -> mesh.obj` replaced the mesh with JSON.
            return f"is a link to {target}, a file of another kind, which writing here would replace; name another file"
    if path.exists() and output.replace is not None:
        return f"exists; {output.replace}, or choose another name"
    return _parent_problem(path.resolve() if path.is_symlink() else path)


def odd_entry(folder: Path) -> tuple[Path, str] | None:
    """The first entry under ``folder`` (in name order, not following links) that is neither a file
    nor a folder, and what it is; None when there is none. A fifo read as a run's record blocked
    ``--resume`` for ever, deaf to signals."""
    for root, folders, files in os.walk(folder):
        folders.sort()
        for name in sorted(folders + files):
            path = Path(root) / name
            try:
                mode = path.lstat().st_mode
            except OSError:
                continue
            if stat.S_ISLNK(mode):
                return path, "a symbolic link"
            if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
                return path, "not a regular file (a fifo, a socket or a device)"
    return None


def utf8_problem(flag: str, name: object, advice: str = "rename it") -> str | None:
    """Why a path given to ``flag`` cannot be used as a name (None when it can): bytes that are not
    UTF-8 (Python holds them as surrogates) reach libE57, laspy, matplotlib and rerun, which
    encode names as UTF-8 and fail halfway through a report."""
    try:
        str(name).encode("utf-8")
    except UnicodeEncodeError:
        shown = str(name).encode("utf-8", "surrogateescape").decode("utf-8", "replace")
        return f"{f'{flag} ' if flag else ''}{shown}: the name is not valid UTF-8; {advice}"
    return None


def _where(path: Path) -> Path:
    """``path`` as the file system finds it: a link and its target, ``a/../b`` and ``b`` are one."""
    try:
        return path.resolve()
    except (OSError, RuntimeError):
        return path.absolute()


def check_outputs(outputs: Iterable[Output], reads: Iterable[tuple[str, Path]] = ()) -> None:
    """Check every output path of a command before it starts (module docstring); creates nothing.

    Parameters
    ----------
    outputs : iterable of Output
    reads : iterable of (str, Path)
        The command's input files by option (``("--scene", Path("d/cloud.ply"))``): none may be a
        file an output writes.

    Raises
    ------
    OutputError
        For the first path that cannot be written or may not be replaced: ``"--out r: its folder
        x does not exist"``; two outputs naming one file; an output that would write over an input.
    """
    outputs = list(outputs)
    seen: dict[Path, Output] = {}
    for output in outputs:
        where = _where(output.path)
        if where in seen:
            raise OutputError(
                f"{seen[where].flag} and {output.flag} both name {_shown(output.path)}: one would overwrite the other"
            )
        seen[where] = output
    written = {where: (output, None) for where, output in seen.items() if output.kind == "file"}
    for output in outputs:
        written.update({_where(output.path / name): (output, name) for name in output.files})
    for flag, path in reads:
        if _where(Path(path)) in written:
            output, name = written[_where(Path(path))]
            what = f"writes {name} in {_shown(output.path)}" if name else f"writes {_shown(output.path)}"
            raise OutputError(
                f"{output.flag} {what}, which is {flag} {_shown(Path(path))}: choose another {output.flag}"
            )
    for output in outputs:
        problem = utf8_problem(output.flag, output.path, "choose another")
        if problem is not None:
            raise OutputError(problem)
        try:
            problem = _problem(output)
        except OSError as exc:  # a name too long for the file system, a loop of links
            problem = f"cannot be used ({exc.strerror or exc})"
        except RuntimeError:  # pathlib's word for a loop of links met while resolving
            problem = "cannot be used (a loop of symbolic links)"
        if problem is not None:
            raise OutputError(f"{output.flag} {_shown(output.path)}: {problem}")


#: This process's claims, by what is locked: (the open descriptor, how many times claimed).
_HELD: dict[tuple, tuple[int, int]] = {}


def _lock_folder() -> Path:
    """Where the lock files of file outputs live: ``/tmp`` itself where there is one, whatever
    ``TMPDIR`` says (a batch job gets its own), shared by every user (sticky, like ``/tmp``)."""
    base = Path("/tmp") if Path("/tmp").is_dir() else Path(tempfile.gettempdir())
    folder = base / "nbs-env-locks"
    if not folder.is_dir():
        folder.mkdir(exist_ok=True)
        with contextlib.suppress(OSError):
            folder.chmod(0o1777)
    return folder


def _holder(st: os.stat_result) -> str:
    """`` (process N)`` of the process holding a flock on the file ``st`` describes, from
    ``/proc/locks`` (Linux); empty where it cannot be told."""
    want = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    with contextlib.suppress(OSError, ValueError):
        for line in Path("/proc/locks").read_text().splitlines():
            fields = line.split()
            if len(fields) > 5 and fields[1] == "FLOCK" and fields[5] == want and fields[4].isdigit():
                return f" (process {fields[4]})"
    return ""


def _open_claim(output: Output) -> tuple[tuple, int, Path | None] | None:
    """What claiming ``output`` locks: ``(key, descriptor, folder made)``; None where nothing can
    be (a path the output checks will refuse, or no lock file to be had).

    A folder is locked itself (made when missing, as the command would make it), so that every name
    of it, a link, ``a/../b`` or another mount of it, is the same lock. A file is replaced by a
    rename, so its lock is a file of its own named by the folder it is in (device and inode) and
    its name."""
    path = Path(output.path)
    if output.kind == "folder":
        made = None
        try:
            if not os.path.lexists(path):
                path.mkdir()
                made = path
            fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
        except OSError:
            if made is not None:
                with contextlib.suppress(OSError):
                    made.rmdir()
            return None
        st = os.fstat(fd)
        return ("folder", st.st_dev, st.st_ino), fd, made
    try:
        parent = os.stat(_where(path).parent)
        key = ("file", parent.st_dev, parent.st_ino, path.name)
        digest = hashlib.sha256(repr(key).encode()).hexdigest()[:32]
        fd = os.open(_lock_folder() / f"{digest}.lock", os.O_RDONLY | os.O_CREAT, 0o666)
    except OSError:
        return None
    with contextlib.suppress(OSError):
        os.fchmod(fd, 0o666)  # another user's command must be able to open it to be refused
    return key, fd, None


@contextlib.contextmanager
def claimed(outputs: Iterable[Output]) -> Iterator[None]:
    """Hold each output for this command while it runs: a second command (another process) given
    the same output meanwhile, by any name, is refused at once, before it looks at what it holds.

    Two commands writing one ``--out`` at once replaced each other's report, or mixed two grids'
    runs in one table, each saying it had written its own. The claim is an advisory lock
    (``fcntl.flock``) on the output folder itself, or for a file on a lock file named by its folder
    and name (:func:`_open_claim`); the operating system lets it go when the process ends, however
    it ends. A folder made for the claim and left empty is removed with it. A process may claim
    what it holds again. Where the platform has no ``flock``, or a path cannot be opened (the
    output checks then say why), nothing is claimed.

    Raises
    ------
    OutputBusyError
        Another process holds one of them: ``"--out r: another nbs command (process 4242) is
        writing it; wait for it to end, or choose another --out"``.
    """
    try:
        import fcntl
    except ImportError:  # not a POSIX system
        yield
        return
    taken: list[tuple[tuple, Path | None]] = []

    def lock(key: tuple, fd: int, made: Path | None, mode: int, output: Output, within: str = "") -> None:
        if key in _HELD:  # this process's own: a flock of a second descriptor would wait on the first
            os.close(fd)
            held, count = _HELD[key]
            _HELD[key] = (held, count + 1)
            taken.append((key, made))
            return
        try:
            fcntl.flock(fd, mode | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                # A file system without flock (some network mounts: ENOLCK, EBADF): not claimed.
                os.close(fd)
                return
            who = _holder(os.fstat(fd))
            os.close(fd)
            if made is not None:
                with contextlib.suppress(OSError):
                    made.rmdir()
            other = "" if output.flag == "--resume" else f", or choose another {output.flag}"
            raise OutputBusyError(
                f"{output.flag} {_shown(Path(output.path))}: another nbs command{who} is writing "
                f"{within or 'it'}; wait for it to end{other}"
            ) from None
        _HELD[key] = (fd, 1)
        taken.append((key, made))

    try:
        for output in outputs:
            # The folders it is in, shared: a scan into a running grid's runs/ wrote into a run's folder
            # (and a grid into a folder a scan is writing within would too).
            for folder in _where(Path(output.path)).parents:
                try:
                    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
                except OSError:  # a folder that cannot be read: not locked, never refused for it
                    continue
                st = os.fstat(fd)
                lock(("folder", st.st_dev, st.st_ino), fd, None, fcntl.LOCK_SH, output, f"{folder}, which holds it")
            opened = _open_claim(output)  # after its folders: one refused makes nothing
            if opened is not None:
                lock(*opened, fcntl.LOCK_EX, output)
        yield
    finally:
        for key, made in reversed(taken):
            fd, count = _HELD[key]
            if count > 1:
                _HELD[key] = (fd, count - 1)
                continue
            del _HELD[key]
            os.close(fd)  # the lock goes with the last descriptor
            if made is not None:  # made for the claim: gone again if the command left it empty
                with contextlib.suppress(OSError):
                    made.rmdir()


class NamedStream:
    """A text stream (``sys.stdout``) whose write errors name it: ``nbs scenes list > full/x`` on a
    full disk says ``stdout: No space left on device``, not ``[Errno 28] No space left on device``.

    ``write`` and ``flush`` raise an ``OSError`` of the same errno (so of the same subclass: a reader
    gone away stays a ``BrokenPipeError``) with ``filename`` the stream's name; the rest is the
    stream's own.
    """

    def __init__(self, stream, name: str = "stdout") -> None:
        self._stream = stream
        self._name = name

    def _named(self, exc: OSError) -> OSError:
        if exc.filename is not None or exc.errno is None:
            return exc
        named = OSError(exc.errno, exc.strerror or str(exc), self._name)
        named.__cause__ = exc
        return named

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except OSError as exc:
            raise self._named(exc)  # noqa: B904  # its cause is set when it is another exception

    def flush(self) -> None:
        try:
            self._stream.flush()
        except OSError as exc:
            raise self._named(exc)  # noqa: B904

    def __getattr__(self, name: str):
        return getattr(self._stream, name)
