"""Atomic file writing and checked reading, used for every file fkn-bench writes.

A file is written to a temporary sibling, flushed and fsynced, then renamed over the target
(``os.replace`` is atomic on POSIX), so readers see the old file or the new one, never a torn one.

Failed writes. Any failure while writing (``OSError``, or the ``RuntimeError`` a library such as
torch raises when its stream fails) leaves the target as it was and raises :class:`WriteError`, one
line naming the path; when the file system is full it is :class:`DiskFullError`, which also says
how much space is free and about how much the write needed. Both are ``OSError`` subclasses, so
existing ``except OSError`` handlers keep working; the command line prints them in one line with
exit code 2. :func:`check_free_space` refuses work up front when its output cannot fit.

Temporary files are named ``.<target name>.<random>[suffix].tmp`` (:data:`TEMPORARY_PATTERN`), and
their writer holds an exclusive ``flock`` on each while it writes. A process killed between
creating one and the rename leaves it behind, unlocked (a lock dies with its process);
:func:`remove_temporaries` deletes such leftovers and skips the files a live writer still holds.
"""

from __future__ import annotations

import errno
import fcntl
import json
import math
import os
import shutil
import tempfile
import tomllib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

__all__ = [
    "atomic_path", "write_bytes_atomic", "write_text_atomic", "write_json_atomic", "read_json", "read_toml", "to_jsonable",
    "WriteError", "DiskFullError", "LockedError", "check_free_space", "directory_lock", "remove_temporaries",
    "format_bytes", "TEMPORARY_PATTERN",
]

TEMPORARY_PATTERN = ".*.tmp"
"""Glob of the temporary files :func:`atomic_path` creates (module docstring)."""

_DISK_FULL = {errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC)}


def format_bytes(count: float) -> str:
    """``count`` bytes for people: ``"812 B"``, ``"3.4 MB"``, ``"1.2 GB"`` (powers of 1000)."""
    for unit, size in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if abs(count) >= size:
            return f"{count / size:.3g} {unit}"
    return f"{int(count)} B"


def _free_bytes(path: Path) -> int | None:
    """Free bytes on the file system of ``path`` (its nearest existing ancestor), or None."""
    for candidate in (path, *path.parents):
        if candidate.exists():
            try:
                return shutil.disk_usage(candidate).free
            except OSError:
                return None
    return None


class WriteError(OSError):
    """A file could not be written; the message names the path and the cause (one line)."""

    def __init__(self, message: str, path: str | Path) -> None:
        super().__init__(message)
        self.path = Path(path)

    def __str__(self) -> str:
        return str(self.args[0])


class DiskFullError(WriteError):
    """The file system filled while writing (or would have): the message names the path, the free
    space and about how much the write needed."""

    def __init__(self, path: str | Path, needed: float | None = None, *, what: str | None = None) -> None:
        path = Path(path)
        free = _free_bytes(path)
        parts = [f"no space left on the device to write {what or path}" + (f" ({path})" if what else "")]
        parts.append(f"{format_bytes(free)} free" if free is not None else "free space unknown")
        if needed:
            parts.append(f"about {format_bytes(needed)} needed")
        super().__init__(": ".join(parts[:1]) + " (" + ", ".join(parts[1:]) + "); free some space or choose another "
                         "directory", path)
        self.free, self.needed = free, needed


class LockedError(OSError):
    """Another process holds the lock of a directory (:func:`directory_lock`)."""


def _is_disk_full(exc: BaseException, directory: Path) -> bool:
    if isinstance(exc, OSError) and exc.errno is not None:  # the system said why (/proc: ENOENT, 0 B "free")
        return exc.errno in _DISK_FULL
    # torch and h5py turn ENOSPC into their own errors ("unexpected pos ...", "file write failed"):
    # a failure while the file system has (almost) nothing left is a full disk
    free = _free_bytes(directory)
    return free is not None and free < 64 * 1024


def check_free_space(directory: str | Path, needed: float, what: str) -> None:
    """Raise :class:`DiskFullError` when the file system of ``directory`` has fewer than ``needed``
    bytes free (plus a 1 MB margin); ``what`` names the output ("the dataset fkn-bench/ds1-full-v0")."""
    directory = Path(directory)
    free = _free_bytes(directory)
    if free is not None and free < needed + 1e6:
        raise DiskFullError(directory, needed, what=what)


@contextmanager
def atomic_path(path: str | Path, suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path`` atomically.

    Use for writers that need a file name (e.g. ``torch.save``, pandas, matplotlib).
    Failures of the file system (and of the writer, when the disk is full) raise
    :class:`WriteError` / :class:`DiskFullError` naming ``path`` (module docstring); other errors of
    the writer propagate unchanged. The target is never left torn.
    """
    target = Path(path)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=suffix + ".tmp", dir=target.parent)
    except OSError as exc:
        raise _write_error(exc, target) from None
    tmp = Path(tmp_name)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)  # a live writer's file: remove_temporaries leaves it alone
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp creates 0600; give the file the usual permissions
        try:
            yield tmp
        except (OSError, RuntimeError) as exc:
            if isinstance(exc, WriteError) or not (isinstance(exc, OSError) or _is_disk_full(exc, target.parent)):
                raise
            raise _write_error(exc, target, _size(tmp)) from None
        try:
            with open(tmp, "rb+") as fh:
                os.fsync(fh.fileno())
            os.replace(tmp, target)
        except OSError as exc:
            raise _write_error(exc, target, _size(tmp)) from None
    finally:
        try:
            tmp.unlink()
        except FileNotFoundError:
            pass
        except OSError:  # pragma: no cover - a directory that vanished or turned read-only
            pass
        os.close(fd)  # releases the lock


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except OSError:
        return 0


def _write_error(exc: BaseException, target: Path, written: int = 0) -> WriteError:
    """The :class:`WriteError` (or :class:`DiskFullError`) for ``exc`` raised writing ``target``."""
    if _is_disk_full(exc, target.parent):
        return DiskFullError(target, written or None)
    reason = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    return WriteError(f"cannot write {target}: {reason}", target)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _write_atomic(path: str | Path, mode: str, write: Callable[[IO[Any]], None]) -> Path:
    with atomic_path(path) as tmp:
        with open(tmp, mode) as fh:
            write(fh)
    return Path(path)


@contextmanager
def directory_lock(directory: str | Path, what: str = "this directory") -> Iterator[Path]:
    """Hold an exclusive advisory lock on ``directory`` (file ``.fkn-bench.lock`` inside it,
    created with the directory) for the block; another process already holding it raises
    :class:`LockedError` at once, naming the directory (no waiting). The lock dies with its
    process, so a killed run never leaves a directory locked. Yields the directory."""
    directory = Path(directory)
    try:
        directory.mkdir(parents=True, exist_ok=True)
        fd = os.open(directory / ".fkn-bench.lock", os.O_RDWR | os.O_CREAT, 0o666 & ~_umask())
    except OSError as exc:
        raise _write_error(exc, directory / ".fkn-bench.lock") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise LockedError(f"{directory} is in use by another fkn-bench process writing {what}: wait for it to "
                              f"finish, or write somewhere else") from None
        yield directory
    finally:
        os.close(fd)  # closing releases the lock


def remove_temporaries(directory: str | Path, *, recursive: bool = True, target: str | None = None) -> list[Path]:
    """Delete the temporary files (:data:`TEMPORARY_PATTERN`; with ``target``, only those of the
    file of that name) that killed writers left under ``directory``, skipping any that a live
    writer holds locked (module docstring); returns the files removed."""
    directory = Path(directory)
    if not directory.is_dir():
        return []
    pattern = f".{glob_escape(target)}.*.tmp" if target else TEMPORARY_PATTERN
    found = directory.rglob(pattern) if recursive else directory.glob(pattern)
    removed = []
    for path in sorted(found):
        if not path.is_file() or path.is_symlink():
            continue
        try:
            fd = os.open(path, os.O_RDONLY)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            path.unlink()
        except OSError:  # locked by a live writer (BlockingIOError), or already gone
            continue
        finally:
            os.close(fd)
        removed.append(path)
    return removed


def glob_escape(name: str) -> str:
    """``name`` with the glob metacharacters ``*?[`` escaped (for :meth:`Path.glob`)."""
    return "".join(f"[{c}]" if c in "*?[" else c for c in name)


def write_bytes_atomic(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically."""
    return _write_atomic(path, "wb", lambda fh: fh.write(data))


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    return _write_atomic(path, "w", lambda fh: fh.write(text))


def to_jsonable(value: Any) -> Any:
    """Convert numpy/torch scalars and arrays, tuples and paths to JSON types; non-finite
    floats become None (JSON has no NaN)."""
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        return to_jsonable(value.tolist())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, (bool, int, str)) or value is None:
        return value
    if hasattr(value, "item"):
        return to_jsonable(value.item())
    raise TypeError(f"cannot convert {type(value).__name__} to JSON")


def write_json_atomic(path: str | Path, document: Any, *, indent: int = 2) -> Path:
    """Write ``document`` as JSON (see :func:`to_jsonable`) atomically, with a final newline."""
    text = json.dumps(to_jsonable(document), indent=indent, allow_nan=False) + "\n"
    return write_text_atomic(path, text)


def read_json(path: str | Path) -> Any:
    """Read a JSON file; raises ``FileNotFoundError`` (missing) or ``ValueError`` (a directory,
    unreadable, not UTF-8, not JSON), naming the file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileNotFoundError(f"file not found: {path}") from None
    except IsADirectoryError:
        raise ValueError(f"{path} is a directory, not a JSON file") from None
    except OSError as exc:
        raise ValueError(f"{path} cannot be read ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path} is not UTF-8 text ({exc.reason})") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path} is not valid JSON: {exc}") from None


def read_toml(path: str | Path, what: str = "config file", error: type[ValueError] = ValueError) -> dict[str, Any]:
    """The TOML document in ``path``. A missing file, a directory, an unreadable file, text that is
    not UTF-8 (TOML's encoding) or invalid TOML raises ``error`` naming ``what`` and the path."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise error(f"{what} not found: {path}") from None
    except IsADirectoryError:
        raise error(f"{what} {path} is a directory, not a TOML file") from None
    except PermissionError:
        raise error(f"{what} {path} cannot be read (permission denied)") from None
    except UnicodeDecodeError as exc:
        raise error(f"{what} {path} is not UTF-8 text ({exc.reason} at byte {exc.start}); TOML files are UTF-8") from None
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{what} {path} is not valid TOML: {exc}") from None
