"""fkn_bench.io: atomic writes, JSON conversion, checked reads."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
import torch

from fkn_bench import io


def _listing(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_atomic_writes_create_parents_and_leave_no_temp_files(tmp_path: Path) -> None:
    target = tmp_path / "a" / "b" / "file.txt"
    assert io.write_text_atomic(target, "héllo\n") == target
    assert target.read_text(encoding="utf-8") == "héllo\n"
    io.write_bytes_atomic(target, b"\x00\x01")
    assert target.read_bytes() == b"\x00\x01"
    io.write_json_atomic(tmp_path / "a" / "doc.json", {"x": 1})
    assert (tmp_path / "a" / "doc.json").read_text() == '{\n  "x": 1\n}\n'
    assert _listing(tmp_path / "a") == ["b", "doc.json"] and _listing(tmp_path / "a" / "b") == ["file.txt"]


def test_atomic_path_for_named_writers(tmp_path: Path) -> None:
    target = tmp_path / "tensor.pt"
    with io.atomic_path(target, suffix=".pt") as tmp:
        assert tmp.parent == tmp_path and tmp.name.startswith(".tensor.pt.") and tmp.name.endswith(".pt.tmp")
        torch.save(torch.arange(3), tmp)
        assert not target.exists()  # only visible once complete
    assert torch.equal(torch.load(target), torch.arange(3))
    assert _listing(tmp_path) == ["tensor.pt"]


def test_a_failed_write_keeps_the_old_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    target = tmp_path / "doc.json"
    io.write_json_atomic(target, {"version": 1})
    before = target.read_bytes()
    # failure inside the writer
    with pytest.raises(RuntimeError, match="writer failed"):
        with io.atomic_path(target) as tmp:
            tmp.write_text("half a docu")
            raise RuntimeError("writer failed")
    # failure while syncing to disk, after everything was written
    def no_fsync(fd: int) -> None:
        raise OSError("device lost")

    monkeypatch.setattr(io.os, "fsync", no_fsync)
    with pytest.raises(OSError, match="device lost"):
        io.write_json_atomic(target, {"version": 2})
    monkeypatch.undo()
    # failure converting the document: nothing written at all
    with pytest.raises(TypeError, match="cannot convert object to JSON"):
        io.write_json_atomic(target, {"bad": object()})
    assert target.read_bytes() == before
    assert _listing(tmp_path) == ["doc.json"]


def test_replace_is_atomic_for_readers(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The target is only ever replaced by os.replace of a complete, synced file."""
    target = tmp_path / "doc.json"
    seen: list[str] = []
    real_replace = os.replace

    def spy(src: str, dst: str) -> None:
        seen.append(Path(src).read_text())
        assert not target.exists() or json.loads(target.read_text()) == {"n": 1}
        real_replace(src, dst)

    io.write_json_atomic(target, {"n": 1})
    monkeypatch.setattr(io.os, "replace", spy)
    io.write_json_atomic(target, {"n": 2})
    assert seen == ['{\n  "n": 2\n}\n'] and json.loads(target.read_text()) == {"n": 2}


def test_to_jsonable() -> None:
    value = {
        1: np.float64(1.5),
        "nan": math.nan,
        "inf": -math.inf,
        "array": np.array([[1.0, np.nan], [np.inf, 2.0]]),
        "ints": np.arange(3, dtype=np.int32),
        "scalar": np.int64(7),
        "bool": np.bool_(True),
        "tuple": (Path("/x/y"), None, "s"),
        "tensor": torch.tensor([0.5, float("nan")]),
        "nested": [{"a": np.float32(0.25)}],
    }
    out = io.to_jsonable(value)
    assert out == {
        "1": 1.5,
        "nan": None,
        "inf": None,
        "array": [[1.0, None], [None, 2.0]],
        "ints": [0, 1, 2],
        "scalar": 7,
        "bool": True,
        "tuple": ["/x/y", None, "s"],
        "tensor": [0.5, None],
        "nested": [{"a": 0.25}],
    }
    assert type(out["scalar"]) is int and type(out["bool"]) is bool
    json.dumps(out, allow_nan=False)  # strict JSON
    with pytest.raises(TypeError, match="cannot convert set to JSON"):
        io.to_jsonable({1, 2})


def test_read_json_names_the_file(tmp_path: Path) -> None:
    good = tmp_path / "good.json"
    good.write_text('{"a": [1, 2]}')
    assert io.read_json(good) == {"a": [1, 2]}
    with pytest.raises(FileNotFoundError, match=r"file not found: .*missing\.json"):
        io.read_json(tmp_path / "missing.json")
    broken = tmp_path / "broken.json"
    broken.write_text('{"a": ')
    with pytest.raises(ValueError, match=r"broken\.json is not valid JSON: Expecting value: line 1 column 7"):
        io.read_json(broken)
    binary = tmp_path / "binary.json"
    binary.write_bytes(b"\xff\xfe{}")
    with pytest.raises(ValueError, match=r"binary\.json is not UTF-8 text"):
        io.read_json(binary)
    round_trip = io.write_json_atomic(tmp_path / "rt.json", {"x": np.array([1.0, np.nan])})
    assert io.read_json(round_trip) == {"x": [1.0, None]}


def test_written_files_get_the_usual_permissions(tmp_path: Path) -> None:
    """mkstemp creates 0600 files; the atomic writers give the result 0666 minus the umask."""
    previous = os.umask(0o022)
    try:
        path = io.write_text_atomic(tmp_path / "shared.txt", "x")
        assert path.stat().st_mode & 0o777 == 0o644
        os.umask(0o077)
        assert io.write_json_atomic(tmp_path / "private.json", {}).stat().st_mode & 0o777 == 0o600
    finally:
        os.umask(previous)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, r"scenario file not found: .*missing\.toml"),
        ("directory", r"scenario file .*x\.toml is a directory, not a TOML file"),
        (b"[scenario.a]\nbase = \"ds1\"\n# caf\xe9\n", r"scenario file .*x\.toml is not UTF-8 text \(invalid continuation byte at byte 31\); TOML files are UTF-8"),
        (b"[scenario.a\n", r"scenario file .*x\.toml is not valid TOML"),
    ],
    ids=["missing", "directory", "not-utf8", "invalid"],
)
def test_read_toml_names_the_file_and_the_problem(tmp_path: Path, content: bytes | str | None, message: str) -> None:
    path = tmp_path / ("missing.toml" if content is None else "x.toml")
    if content == "directory":
        path.mkdir()
    elif isinstance(content, bytes):
        path.write_bytes(content)
    with pytest.raises(KeyError, match=message):
        io.read_toml(path, "scenario file", KeyError)  # type: ignore[arg-type]
    assert io.read_toml(_toml(tmp_path), "x") == {"a": 1}


def _toml(tmp_path: Path) -> Path:
    path = tmp_path / "good.toml"
    path.write_text("a = 1\n", encoding="utf-8")
    return path


def test_a_full_disk_is_one_error_naming_the_path_and_the_space(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """ENOSPC while writing (issue 34, finding 4): one :class:`io.DiskFullError` (an OSError)
    naming the target, the free space and the bytes the write needed; the old file stays and no
    temporary file is left."""
    import errno

    target = io.write_text_atomic(tmp_path / "doc.txt", "old")

    def full(fd: int) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(io.os, "fsync", full)
    with pytest.raises(io.DiskFullError) as caught:
        io.write_text_atomic(target, "x" * 5000)
    message = str(caught.value)
    assert "\n" not in message and str(target) in message and "free" in message and "5 kB needed" in message
    assert isinstance(caught.value, OSError) and caught.value.path == target
    assert target.read_text() == "old" and _listing(tmp_path) == ["doc.txt"]


def test_a_library_error_is_a_full_disk_only_when_the_disk_is_full(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """torch reports ENOSPC as ``RuntimeError("... unexpected pos ...")``: with (almost) no free
    space it becomes :class:`io.DiskFullError`; with space left it is the library's own error."""
    with pytest.raises(RuntimeError, match="unexpected pos"):
        with io.atomic_path(tmp_path / "t.pt"):
            raise RuntimeError("unexpected pos 81792 vs 81684")
    monkeypatch.setattr(io, "_free_bytes", lambda path: 0)
    with pytest.raises(io.DiskFullError, match=r"no space left on the device to write .*t\.pt \(0 B free"):
        with io.atomic_path(tmp_path / "t.pt"):
            raise RuntimeError("unexpected pos 81792 vs 81684")
    with pytest.raises(io.DiskFullError, match="about 2 GB needed"):
        io.check_free_space(tmp_path, 2e9, "the dataset x")
    assert _listing(tmp_path) == []


def test_other_write_failures_name_the_path(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(io.WriteError, match=r"cannot write .*file/sub/doc\.json: (Not a directory|File exists)") as caught:
        io.write_json_atomic(blocker / "sub" / "doc.json", {})
    assert not isinstance(caught.value, io.DiskFullError)


def test_the_directory_lock_refuses_a_second_holder_and_temporaries_are_removed(tmp_path: Path) -> None:
    """:func:`io.directory_lock` is exclusive across open file descriptions (a second process, or
    a second holder in this one) and released on exit; :func:`io.remove_temporaries` removes the
    leftovers of killed atomic writers, nothing else."""
    stray = tmp_path / "cells" / ".a.csv.x1y2.tmp"
    stray.parent.mkdir()
    stray.write_text("half")
    keep = tmp_path / "cells" / "a.csv"
    keep.write_text("whole")
    with io.directory_lock(tmp_path, "results"):
        with pytest.raises(io.LockedError, match=r"is in use by another fkn-bench process"):
            with io.directory_lock(tmp_path):
                pass
        assert io.remove_temporaries(tmp_path) == [stray]
    with io.directory_lock(tmp_path):  # released
        pass
    assert sorted(p.name for p in (tmp_path / "cells").iterdir()) == ["a.csv"]


def test_a_live_writers_temporary_is_never_removed(tmp_path: Path) -> None:
    """A writer holds a lock on its temporary file while it writes, so that a concurrent
    :func:`io.remove_temporaries` (another command cleaning up after a killed one) skips it; a
    dead writer's leftover, and with ``target`` only that file's, is removed."""
    dead = tmp_path / ".doc.json.abc123.tmp"
    dead.write_text("half")
    other = tmp_path / ".notes.md.abc123.tmp"
    other.write_text("half")
    with io.atomic_path(tmp_path / "doc.json") as live:
        live.write_text("{}")
        assert io.remove_temporaries(tmp_path, target="doc.json") == [dead]
        assert live.exists() and other.exists()
    assert (tmp_path / "doc.json").read_text() == "{}"
    assert io.remove_temporaries(tmp_path) == [other] and _listing(tmp_path) == ["doc.json"]
