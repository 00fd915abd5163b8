"""Paths and writes that fail cleanly and never leave half a file: the one place where sorofem
checks a file name and writes a file.

Every output goes through :func:`atomic_path` (or :func:`write_text`, built on it): the data go
to a new temporary file in the same folder, which is flushed to the disk and then renamed over
the final name. A reader therefore sees the old file or the new one, never a mix; an
interrupted or failed write leaves the old file as it was; and writing never goes *through*
the existing file, so another hard link to it (a scene file linked as ``summary.json``, say)
keeps its data. Append-only records (the history of an estimate) go through
:func:`append_line`: one ``write`` of a whole line, then ``fsync``, and on failure the file is
cut back to its previous end.

Internal: :mod:`sorofem.io` re-exports :func:`atomic_path`, :func:`write_text` and
:func:`check_path` for users.
"""

from __future__ import annotations

import errno as errnos
import os
import secrets
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

from ._validate import describe
from .errors import InputError, OutputError

__all__ = ["MAX_NAME_BYTES", "MAX_PATH_BYTES", "check_path", "atomic_path", "write_text", "append_line",
           "output_error", "fsync_folder"]

#: Longest file or folder name (one path component), bytes of UTF-8: Linux's NAME_MAX.
MAX_NAME_BYTES = 255
#: Longest path, bytes of UTF-8: Linux's PATH_MAX.
MAX_PATH_BYTES = 4096

_REASONS = {
    errnos.ENOSPC: "no space left on the device",
    errnos.EFBIG: "the file would exceed the file-size limit",
    errnos.EDQUOT: "the disk quota is exceeded",
    errnos.EACCES: "permission denied",
    errnos.EPERM: "operation not permitted",
    errnos.EROFS: "the file system is read-only",
    errnos.EISDIR: "it is a folder",
    errnos.ENOTDIR: "a part of the path is not a folder",
    errnos.ENOENT: "its folder does not exist",
    errnos.ENAMETOOLONG: "the name is too long",
    errnos.EIO: "input/output error",
}


def check_path(value: Any, name: str) -> Path:
    """A file name given by the user, as a :class:`~pathlib.Path`, checked before any work.

    Raises
    ------
    InputError
        Not a ``str`` or ``os.PathLike``, empty, a NUL byte in it, a component longer than
        :data:`MAX_NAME_BYTES` bytes or the whole longer than :data:`MAX_PATH_BYTES` bytes.
    """
    if not isinstance(value, (str, os.PathLike)):
        raise InputError(f"{name}: expected a file name (str or path), got {describe(value)}")
    try:
        text = os.fspath(value)
    except TypeError as exc:
        raise InputError(f"{name}: expected a file name (str or path), got {describe(value)} ({exc})") from None
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    if not text:
        raise InputError(f"{name}: expected a file name, got an empty string")
    if "\0" in text:
        raise InputError(f"{name}: a file name cannot contain a NUL byte, got {text!r}")
    encoded = os.fsencode(text)
    if len(encoded) > MAX_PATH_BYTES:
        raise InputError(f"{name}: the path is {len(encoded)} bytes long; at most {MAX_PATH_BYTES} are allowed")
    for part in Path(text).parts:
        size = len(os.fsencode(part))
        if size > MAX_NAME_BYTES:
            raise InputError(
                f"{name}: the path component {part[:40]!r}... is {size} bytes long; a file or folder name has at "
                f"most {MAX_NAME_BYTES}"
            )
    return Path(text)


def output_error(path: Path, exc: OSError) -> OutputError:
    """An :class:`OutputError` naming ``path`` and what the system said."""
    reason = _REASONS.get(exc.errno or 0, exc.strerror or type(exc).__name__)
    return OutputError(f"cannot write {path}: {reason}", path=path, errno=exc.errno)


def _check_target(path: Path) -> None:
    if path.is_dir():
        raise OutputError(f"cannot write {path}: it is a folder (give a file name)", path=path, errno=errnos.EISDIR)
    folder = path.parent
    if folder.exists() and not folder.is_dir():
        raise OutputError(f"cannot write {path}: {folder} is not a folder", path=path, errno=errnos.ENOTDIR)


def fsync_folder(folder: Path) -> None:
    """Make a rename in ``folder`` durable (best effort: some file systems refuse)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path to write ``path``'s new content to; renamed over ``path`` when the block
    ends normally.

    The temporary file is in the same folder (a rename within one file system is atomic),
    hidden (its name starts with a dot) and ends with the same suffix, so writers that pick
    the format by the suffix (meshio, matplotlib) write the right one. It already exists (empty)
    when the block starts. After the block it is flushed to the disk (``fsync``) and renamed;
    if the block raises (an error, Ctrl-C), the temporary file is removed and ``path`` is left
    as it was.

    Raises
    ------
    OutputError
        The file cannot be written (disk full, file-size limit, permission, read-only file
        system, ``path`` is a folder, its folder is missing): the message names ``path``.

    Examples
    --------
    >>> from sorofem.io import atomic_path
    >>> with atomic_path("/tmp/numbers.txt") as tmp:
    ...     _ = tmp.write_text("1 2 3\\n")
    >>> open("/tmp/numbers.txt").read()
    '1 2 3\\n'
    """
    path = Path(path)
    _check_target(path)
    temporary = path.with_name(f".{path.stem}.tmp-{secrets.token_hex(4)}{path.suffix}")
    try:
        os.close(os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
    except OSError as exc:
        raise output_error(path, exc) from None
    try:
        yield temporary
        fd = os.open(temporary, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(temporary, path)
    except OSError as exc:
        _remove(temporary)
        if isinstance(exc, OutputError):
            raise
        raise output_error(path, exc) from None
    except BaseException:
        _remove(temporary)
        raise
    fsync_folder(path.parent)


def _remove(path: Path) -> None:
    try:
        path.unlink()
    except OSError:
        pass


def write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically (:func:`atomic_path`)."""
    with atomic_path(path) as temporary:
        with open(temporary, "w", encoding="utf-8") as fh:
            fh.write(text)


def append_line(path: str | os.PathLike[str], line: str) -> None:
    """Append one line (``line`` plus a newline) to ``path`` durably: a single ``write`` of the
    whole record, then ``fsync``. A failure cuts the file back to its previous end, so it
    never keeps a partial record; a crash (SIGKILL, power) can still tear the last line, which
    the reader must ignore (:func:`sorofem.estimate` does, and says so).

    Raises
    ------
    OutputError
        The line cannot be written (the file is unchanged).
    """
    path = Path(path)
    data = (line.rstrip("\n") + "\n").encode("utf-8")
    try:
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
    except OSError as exc:
        raise output_error(path, exc) from None
    try:
        end = os.fstat(fd).st_size
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view):]
            os.fsync(fd)
        except OSError as exc:
            try:
                os.ftruncate(fd, end)
            except OSError:
                pass
            raise output_error(path, exc) from None
    finally:
        os.close(fd)
