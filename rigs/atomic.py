"""The one atomic writer: every file the toolkit writes goes through this module.

A file is written under a unique hidden temporary name in its destination folder
(``.NAME.tmp-<random>.SUFFIX``, created with ``O_EXCL`` by :func:`tempfile.mkstemp`, so two
writers, threads or processes, never share one), flushed with ``fsync`` when asked, and
renamed over ``NAME`` with :func:`os.replace`. A reader therefore sees the old file or the
new one, never a torn one, and a crash at any instant leaves at most a temporary file that
:func:`is_temporary` recognises and :func:`remove_temporaries` clears.

>>> import tempfile, pathlib
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> atomic_write_json(d / "a.json", {"x": 1}).read_text()
'{\\n  "x": 1\\n}\\n'
>>> with atomic_path(d / "b.txt") as tmp:
...     _ = tmp.write_text("written by name")
>>> (d / "b.txt").read_text(), sorted(p.name for p in d.iterdir())
('written by name', ['a.json', 'b.txt'])
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from os import PathLike
from pathlib import Path
from typing import IO, Any, Iterator

__all__ = [
    "TEMP_MARK",
    "atomic_open",
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_json",
    "atomic_write_text",
    "fsync_dir",
    "is_temporary",
    "remove_temporaries",
]

#: Marker in every temporary name: ``.NAME`` + ``TEMP_MARK`` + random + suffix.
TEMP_MARK = ".tmp-"


def is_temporary(name: str | PathLike) -> bool:
    """Whether a file name is one of this module's temporary names.

    >>> is_temporary(".000001.png.tmp-k2j4_x.png"), is_temporary("000001.png")
    (True, False)
    """
    name = Path(name).name
    return name.startswith(".") and TEMP_MARK in name


def remove_temporaries(folder: str | PathLike, recursive: bool = False) -> list[Path]:
    """Delete the temporary files a killed writer left in ``folder`` (and, with ``recursive``,
    in its sub-folders); return what was removed. Only for a folder no other writer is using."""
    folder = Path(folder)
    removed = []
    if folder.is_dir():
        for p in folder.rglob(f".*{TEMP_MARK}*") if recursive else folder.iterdir():
            if is_temporary(p.name) and p.is_file():
                with contextlib.suppress(OSError):
                    p.unlink()
                    removed.append(p)
    return removed


def fsync_dir(folder: str | PathLike) -> None:
    """Flush a folder's entries (a rename) to stable storage."""
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _naming(exc: OSError, path: Path) -> OSError:
    """The same error with the destination named (errno kept, so ENOSPC stays ENOSPC)."""
    if str(path) in str(exc):
        return exc
    return OSError(exc.errno, f"{exc.strerror or exc}: writing {path}")


def _mkstemp(path: Path) -> tuple[int, Path]:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}{TEMP_MARK}", suffix=path.suffix, dir=path.parent)
    return fd, Path(tmp)


def _commit(tmp: Path, path: Path, fsync: bool) -> None:
    if fsync:
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    os.replace(tmp, path)
    if fsync:
        fsync_dir(path.parent)


@contextlib.contextmanager
def atomic_path(path: str | PathLike, *, fsync: bool = True, mkdir: bool = False) -> Iterator[Path]:
    """Yield a unique temporary path beside ``path`` (same suffix) for code that writes by
    name (OpenCV, OpenEXR, ``numpy.savez``, a PLY writer); on success it is flushed and
    renamed onto ``path``, on any error it is removed and ``path`` is left as it was.

    ``mkdir`` creates the destination folder first.
    """
    path = Path(path)
    if mkdir:
        path.parent.mkdir(parents=True, exist_ok=True)
    try:
        fd, tmp = _mkstemp(path)
    except OSError as exc:
        raise _naming(exc, path) from exc
    os.close(fd)
    try:
        yield tmp
        _commit(tmp, path, fsync)
    except OSError as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise _naming(exc, path) from exc
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def atomic_open(
    path: str | PathLike, mode: str = "w", *, fsync: bool = True, mkdir: bool = False,
    encoding: str | None = "utf-8", newline: str | None = None,
) -> Iterator[IO]:
    """``open()`` for writing, atomically: the file appears under ``path`` only when the
    ``with`` block ends without an error. ``mode`` is ``"w"`` (text) or ``"wb"``."""
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open: mode must be 'w' or 'wb', got {mode!r}")
    with atomic_path(path, fsync=fsync, mkdir=mkdir) as tmp:
        if mode == "wb":
            with open(tmp, "wb") as f:
                yield f
        else:
            with open(tmp, "w", encoding=encoding, newline=newline) as f:
                yield f


def _write_all(fd: int, data: bytes | memoryview) -> None:
    """Write every byte of ``data`` to ``fd`` (``os.write`` may write fewer)."""
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


def atomic_write_bytes(path: str | PathLike, data: bytes | memoryview, *, fsync: bool = True,
                       mkdir: bool = False) -> Path:
    """Write ``data`` to ``path`` atomically (see the module docstring); return ``path``."""
    path = Path(path)
    with atomic_path(path, fsync=fsync, mkdir=mkdir) as tmp:
        fd = os.open(tmp, os.O_WRONLY | os.O_TRUNC)
        try:
            _write_all(fd, data)
        finally:
            os.close(fd)
    return path


def atomic_write_text(path: str | PathLike, text: str, *, fsync: bool = True, mkdir: bool = False) -> Path:
    """UTF-8 text version of :func:`atomic_write_bytes`."""
    return atomic_write_bytes(path, text.encode("utf-8"), fsync=fsync, mkdir=mkdir)


def atomic_write_json(path: str | PathLike, obj: Any, *, fsync: bool = True, mkdir: bool = False,
                      indent: int | None = 2, **dumps: Any) -> Path:
    """Write ``obj`` as JSON (UTF-8, final newline; NaN refused) atomically."""
    text = json.dumps(obj, indent=indent, allow_nan=False, **dumps) + "\n"
    return atomic_write_text(path, text, fsync=fsync, mkdir=mkdir)
