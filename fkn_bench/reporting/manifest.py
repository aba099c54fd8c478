"""Output directories shared with people: fkn-bench replaces only the files it wrote there.

A command that writes a set of named files into a directory the user gives (``fkn-bench
leaderboard --out``) keeps a manifest there, :data:`MANIFEST`: the name and SHA-256 of every file
it wrote. :func:`write_files` then writes a file only when

* it does not exist, or
* it still has the content fkn-bench wrote (its SHA-256 is the manifest's), or
* it already holds exactly the new content (nothing is lost by writing it);

any other existing file -- one the user wrote, or one edited since -- is refused with
:class:`ForeignFileError` (one line naming it) before anything is written, unless ``force``
(then it is replaced and from then on listed). Files are never deleted; the manifest keeps
listing files an earlier run wrote. Names are single file names (no separator, not hidden), so
nothing is written outside the directory.

Kills: the manifest is written first with the new files' hashes as ``pending``, then the files
(atomically, unchanged ones skipped), then the manifest without ``pending``; a file holding either
hash is fkn-bench's, so a run killed at any point is rerun without ``--force`` and ends as an
uninterrupted one. Writers hold :func:`fkn_bench.io.directory_lock` on the directory (a second
writer is refused) and remove stray temporary files of killed writes first.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from fkn_bench.io import directory_lock, read_json, remove_temporaries, write_bytes_atomic, write_json_atomic

__all__ = ["MANIFEST", "ForeignFileError", "check_files", "write_files"]

MANIFEST = ".fkn-bench-files.json"
"""The manifest's file name (module docstring)."""
_FORMAT = "fkn-bench-files"


class ForeignFileError(ValueError):
    """An existing file fkn-bench did not write (or that was edited since) is in the way."""


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _manifest(directory: Path) -> dict[str, Any]:
    """The manifest's ``files`` and ``pending`` maps (empty when there is none or it is not one)."""
    try:
        document = read_json(directory / MANIFEST)
    except (OSError, ValueError):
        return {"files": {}, "pending": {}}
    if not isinstance(document, dict) or document.get("format") != _FORMAT:
        return {"files": {}, "pending": {}}
    return {part: {str(k): str(v) for k, v in (document.get(part) or {}).items()} for part in ("files", "pending")}


def _check_name(name: str) -> None:
    if not name or name != Path(name).name or name.startswith(".") or "\\" in name:
        raise ValueError(f"{name!r} is not a plain file name: an output file must stay in its directory")


def _conflict(directory: Path, name: str, new: bytes | None, manifest: dict[str, Any], force: bool) -> bool:
    """Whether ``name`` differs from ``new`` (None: unknown yet) and may be written; raises
    :class:`ForeignFileError` when it is somebody else's (module docstring)."""
    path = directory / name
    if path.is_dir():
        raise ForeignFileError(f"{path} is a directory; fkn-bench would write a file of that name there")
    try:
        current = path.read_bytes()
    except FileNotFoundError:
        return True
    except OSError as exc:
        raise ForeignFileError(f"{path} cannot be read ({exc.strerror or exc}); fkn-bench would replace it") from None
    if new is not None and current == new:
        return False
    ours = _sha256(current) in (manifest["files"].get(name), manifest["pending"].get(name))
    if not (ours or force):
        raise ForeignFileError(
            f"{path} exists and fkn-bench did not write it (or it was edited since; {MANIFEST} lists what fkn-bench "
            f"wrote): move it away, choose another --out, or pass --force to replace it"
        )
    return True


def _check_directory(directory: Path) -> None:
    if directory.exists() and not directory.is_dir():
        raise ForeignFileError(f"{directory} is a file, not a directory")


def _settled(directory: Path, manifest: dict[str, Any]) -> dict[str, str]:
    """The manifest's files as they stand: a pending file that a killed run did write counts
    with its new hash, one it did not keeps the hash it had."""
    files = dict(manifest["files"])
    for name, digest in manifest["pending"].items():
        try:
            written = _sha256((directory / name).read_bytes()) == digest
        except OSError:
            written = False
        if written or name not in files:
            files[name] = digest
    return files


def check_files(directory: str | Path, names: list[str], *, force: bool = False) -> None:
    """Refuse early, writing nothing, when :func:`write_files` would refuse one of ``names``
    whatever its content (for commands that compute for long before they write)."""
    directory = Path(directory)
    _check_directory(directory)
    manifest = _manifest(directory)
    for name in names:
        _check_name(name)
        _conflict(directory, name, None, manifest, force)


def write_files(directory: str | Path, files: Mapping[str, str | bytes], *, force: bool = False,
                what: str = "its output") -> list[Path]:
    """Write ``files`` (``{file name: text or bytes}``, text as UTF-8) into ``directory``
    (created) under the rules of the module docstring; returns every file's path, in name order,
    written or already identical. Raises :class:`ForeignFileError` (nothing written),
    :class:`fkn_bench.io.LockedError` or :class:`fkn_bench.io.WriteError`."""
    directory = Path(directory)
    data = {name: text.encode("utf-8") if isinstance(text, str) else bytes(text) for name, text in sorted(files.items())}
    _check_directory(directory)
    for name in data:
        _check_name(name)
    manifest = _manifest(directory)
    for name, content in data.items():  # before the lock file is made in somebody else's directory
        _conflict(directory, name, content, manifest, force)
    with directory_lock(directory, what):
        remove_temporaries(directory, recursive=False)
        manifest = _manifest(directory)
        changed = [name for name, content in data.items() if _conflict(directory, name, content, manifest, force)]
        hashes = {name: _sha256(content) for name, content in data.items()}
        settled = _settled(directory, manifest)
        final = {**settled, **hashes}  # files written earlier stay listed
        if changed:
            _write_manifest(directory, settled, {n: hashes[n] for n in changed})
            for name in changed:
                write_bytes_atomic(directory / name, data[name])
        if changed or manifest["pending"] or manifest["files"] != final:
            _write_manifest(directory, final, {})
    return [directory / name for name in data]


def _write_manifest(directory: Path, files: dict[str, str], pending: dict[str, str]) -> None:
    document: dict[str, Any] = {
        "format": _FORMAT,
        "note": "files fkn-bench wrote here, with their SHA-256: it replaces only these (or with --force)",
        "files": dict(sorted(files.items())),
    }
    if pending:
        document["pending"] = dict(sorted(pending.items()))
    write_json_atomic(directory / MANIFEST, document)
