"""Files written whole or not at all: the report's and ``nbs compare``'s outputs.

Every file goes to a temporary file in its own folder (``.STEM.XXXXXXXX.tmp.SUFFIX``, :func:`temporary_path`:
hidden, and with the final suffix, by which matplotlib and laspy choose the format), is flushed to the disk
(``fsync``) and then renamed onto its name (``os.replace``, atomic on POSIX and Windows within one
file system). A full disk, a signal or a crash while writing leaves the previous file as it was, or
no file, and no partial one: the temporary file is removed whatever stopped the write.

:func:`write_bytes` and :func:`write_text` write what is in memory; :func:`replacing` lends a
temporary path to a library that writes the file itself (libE57, laspy, matplotlib). An ``OSError``
names the file that was being written, never the temporary one.

A path that is a symbolic link is written through by default: a file the user named
(``--out plan.json``, a link to where the plans live) is the link's target. A file a command owns
inside its own folder (``nbs compare``'s ``metrics.json``, ``table.md``) is written with
``follow_links=False``: a link found there is replaced by the file, and what it pointed to, perhaps
outside the folder, is left as it was.
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
import shutil
from collections.abc import Iterator
from pathlib import Path

__all__ = ["replacing", "temporary_path", "write_bytes", "write_text"]

#: Bytes per ``os.write`` call: large enough to be fast, small enough that a failure leaves a
#: short partial temporary file to remove.
CHUNK = 1 << 20


def _write(fd: int, data: memoryview) -> int:
    """The one place where bytes reach a file: ``os.write`` (the tests make it fail halfway)."""
    return os.write(fd, data)


#: The longest file name most file systems take (ext4, XFS, APFS, NTFS: 255 bytes or UTF-16 units).
NAME_MAX = 255


def _name_max(folder: Path) -> int:
    try:
        return min(NAME_MAX, os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError, AttributeError):  # no such folder yet, or no pathconf (Windows)
        return NAME_MAX


def temporary_path(path: str | os.PathLike[str], tag: str = "tmp") -> Path:
    """A fresh hidden name beside ``path`` to write it under before the rename:
    ``.STEM.XXXXXXXX.TAG.SUFFIX``, with the final suffix (by which matplotlib, laspy and rerun
    choose the format) and the stem shortened to fit the folder's longest name: a legal name of
    255 bytes must not fail because its temporary name is longer.

    Parameters
    ----------
    path : str or PathLike
        The file that will be written.
    tag : str
        What the temporary file is (``tmp``, ``partial``).

    Returns
    -------
    Path
    """
    path = Path(path)
    middle = f".{secrets.token_hex(4)}.{tag}"
    suffix = path.suffix
    room = _name_max(path.parent) - len(f".{middle}{suffix}".encode())
    if room < 0:  # a suffix as long as a name: not a format any writer reads by it
        suffix, room = "", _name_max(path.parent) - len(f".{middle}".encode())
    stem = path.stem.encode()[:room].decode(errors="ignore")  # whole characters only
    return path.with_name(f".{stem}{middle}{suffix}")


def _named(exc: OSError, path: Path) -> OSError:
    """``exc`` naming ``path`` (the file the user knows), of the same OSError subclass (by errno)."""
    if exc.errno is None:
        return exc
    return OSError(exc.errno, exc.strerror or str(exc), str(path))


#: Free bytes below which a library's failure to write is taken for a full disk: more than the
#: largest block the writers used here flush at once (a LAZ chunk, libE57's pages, numpy's zip members).
NEARLY_FULL = 8 << 20


def _nearly_full(folder: Path) -> bool:
    try:
        return shutil.disk_usage(folder).free < NEARLY_FULL
    except OSError:
        return False


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_folder(folder: Path) -> None:
    """Make the rename itself durable; some systems (Windows) open no folder, which is fine."""
    with contextlib.suppress(OSError):
        _fsync(folder)


@contextlib.contextmanager
def replacing(
    path: str | os.PathLike[str], writer_errors: tuple[type[Exception], ...] = (), *, follow_links: bool = True
) -> Iterator[Path]:
    """A temporary path beside ``path`` to write the file to; renamed onto ``path`` on success.

    Parameters
    ----------
    path : str or PathLike
        The file to write; its folder must exist.
    writer_errors : tuple of exception classes
        The errors by which the library writing the file reports that it could not (libE57's
        ``E57Exception``, lazrs' ``LazrsError``): raised as an ``OSError`` naming ``path``,
        ``errno.ENOSPC`` where the disk is (nearly) full, ``errno.EIO`` otherwise.
    follow_links : bool
        True: a link at ``path`` is written through (its target is replaced). False: the link itself
        is replaced by the new file and its target left alone (the files of a folder the command owns).

    Yields
    ------
    Path
        The temporary file's path, in ``path``'s folder and with its suffix. The block must create it.

    Raises
    ------
    OSError
        The block's (or one of ``writer_errors``), or the flush's or rename's, naming ``path``.
        Whatever the block raises (a ``KeyboardInterrupt`` included), the temporary file is removed
        and ``path`` left as it was.
    """
    # Through a link to its file: renamed onto the link itself, the new file would replace the link.
    path = Path(os.path.realpath(path)) if follow_links else Path(path)
    if (follow_links or not path.is_symlink()) and path.exists() and not path.is_file():
        what = "a folder" if path.is_dir() else "a device, a fifo or a socket"
        raise OSError(errno.EINVAL, f"not a regular file ({what}): nothing is written", str(path))
    temporary = temporary_path(path)
    try:
        yield temporary
        _fsync(temporary)
        os.replace(temporary, path)
    except BaseException as exc:
        # Measured before the partial file is removed: a library's own error (lazrs' IoError,
        # libE57's E57Exception) on a disk with nothing left is a full disk, and says so.
        full = isinstance(exc, Exception) and not isinstance(exc, OSError) and _nearly_full(temporary.parent)
        failed = isinstance(exc, writer_errors)
        with contextlib.suppress(OSError):
            temporary.unlink(missing_ok=True)
        if isinstance(exc, OSError) and exc.filename in (None, str(temporary)):
            raise _named(exc, path) from exc
        if full:
            raise OSError(errno.ENOSPC, f"{os.strerror(errno.ENOSPC)} ({type(exc).__name__})", str(path)) from exc
        if failed:
            first = (str(exc).strip().splitlines() or [""])[0]
            detail = f"{type(exc).__name__}: {first}" if first else type(exc).__name__
            raise OSError(errno.EIO, f"could not be written ({detail})", str(path)) from exc
        raise
    _fsync_folder(path.parent)


def write_bytes(
    path: str | os.PathLike[str], data: bytes | bytearray | memoryview, *, follow_links: bool = True
) -> Path:
    """Write ``data`` to ``path`` whole or not at all (module docstring); returns ``path``.

    ``follow_links=False``: a link at ``path`` is replaced, not written through (:func:`replacing`).

    Raises
    ------
    OSError
        Naming ``path`` (a full disk: ``errno.ENOSPC``); ``path`` is left as it was.
    """
    path = Path(path)
    view = memoryview(data).cast("B")
    with replacing(path, follow_links=follow_links) as temporary:
        fd = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
        try:
            done = 0
            while done < len(view):
                done += _write(fd, view[done : done + CHUNK])
        finally:
            os.close(fd)
    return path


def write_text(path: str | os.PathLike[str], text: str, *, follow_links: bool = True) -> Path:
    """Write ``text`` as UTF-8 to ``path`` whole or not at all (:func:`write_bytes`); returns ``path``."""
    return write_bytes(path, text.encode("utf-8"), follow_links=follow_links)
