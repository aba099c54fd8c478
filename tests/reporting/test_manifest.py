"""Output directories shared with people (issue 34, findings 1 and 6): only fkn-bench's own files
are replaced, nothing escapes, and a write killed anywhere is finished by the next one."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fkn_bench.reporting.manifest import MANIFEST, ForeignFileError, check_files, write_files

FILES = {"README.md": "# index\n", "ds1.md": "# ds1\n", "results.csv": "a,b\n1,2\n"}


def _contents(directory: Path) -> dict[str, str]:
    return {p.name: p.read_text() for p in directory.iterdir() if p.is_file() and p.name != ".fkn-bench.lock"}


def test_files_of_somebody_else_are_refused_and_nothing_is_written(tmp_path: Path) -> None:
    (tmp_path / "README.md").write_text("MINE\n")
    with pytest.raises(ForeignFileError, match=rf"^{tmp_path}/README.md exists and fkn-bench did not write it .* "
                                               r"pass --force to replace it$"):
        write_files(tmp_path, FILES)
    assert _contents(tmp_path) == {"README.md": "MINE\n"}  # no other file, no lock file, no manifest
    with pytest.raises(ForeignFileError, match="README.md exists"):
        check_files(tmp_path, ["README.md"])
    write_files(tmp_path, FILES, force=True)
    assert _contents(tmp_path)["README.md"] == "# index\n"
    write_files(tmp_path, {**FILES, "README.md": "# new index\n"})  # ours now


def test_own_files_are_replaced_until_somebody_edits_one(tmp_path: Path) -> None:
    write_files(tmp_path, FILES)
    assert set(json.loads((tmp_path / MANIFEST).read_text())["files"]) == set(FILES)
    write_files(tmp_path, {**FILES, "ds1.md": "# ds1, again\n"})
    (tmp_path / "results.csv").write_text("edited by hand\n")
    with pytest.raises(ForeignFileError, match="results.csv exists and fkn-bench did not write it"):
        write_files(tmp_path, {**FILES, "results.csv": "a,b\n3,4\n"})
    assert (tmp_path / "results.csv").read_text() == "edited by hand\n"


def test_a_file_already_holding_the_new_text_is_adopted(tmp_path: Path) -> None:
    for name, text in FILES.items():  # e.g. committed before the manifest existed
        (tmp_path / name).write_text(text)
    write_files(tmp_path, FILES)
    write_files(tmp_path, {**FILES, "README.md": "# changed\n"})


@pytest.mark.parametrize("name", ["../escape.md", "sub/x.md", ".hidden", "..", ""])
def test_names_that_would_leave_the_directory_are_refused(tmp_path: Path, name: str) -> None:
    with pytest.raises(ValueError, match="not a plain file name"):
        write_files(tmp_path / "out", {name: "x"})
    assert not (tmp_path / "escape.md").exists() and not (tmp_path / "out").exists()


def test_a_write_killed_anywhere_is_finished_by_the_next_one(tmp_path: Path, kill_at_write) -> None:  # noqa: ANN001
    old, new = FILES, {**FILES, "README.md": "# new\n", "ds2.md": "# ds2\n"}
    write_files(tmp_path / "whole", old)
    write_files(tmp_path / "whole", new)
    expected = _contents(tmp_path / "whole")
    for n in range(1, 5):  # the pending manifest, the 2 changed files, the final manifest
        out = tmp_path / f"killed-{n}"
        write_files(out, old)
        with kill_at_write(n) as written:
            write_files(out, new)
        assert len(written) == n - 1, n
        write_files(out, new)  # no --force needed
        assert _contents(out) == expected, n
