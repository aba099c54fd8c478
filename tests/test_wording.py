"""Option spellings (keyword or flag) and one-line warnings (fkn_bench.wording)."""

from __future__ import annotations

import io
import warnings

from fkn_bench import wording


def test_options_are_spelled_for_their_reader() -> None:
    assert wording.option("repair") == "repair=True" and wording.option("time_source", "log") == "time_source='log'"
    assert wording.option_name("quaternion_tolerance") == "quaternion_tolerance"
    with wording.cli_words():
        assert wording.option("repair") == "--repair" and wording.option("time_source", "log") == "--time-source log"
        assert wording.option_name("quaternion_tolerance") == "--quaternion-tolerance"
        assert wording.option("no_such_flag", 3) == "no_such_flag=3"  # no flag: the keyword
    assert wording.option("repair") == "repair=True"


def test_one_line_warnings_and_their_worker_initializer() -> None:
    assert wording.worker_initializer() == (None, ())  # Python's display: workers keep theirs
    before = warnings.showwarning
    with wording.one_line_warnings("fkn-bench run"):
        initializer, args = wording.worker_initializer()
        assert initializer is wording.install_one_line_warnings and args == ("fkn-bench run",)
        stream = io.StringIO()
        wording.install_one_line_warnings("worker", stream)
        warnings.warn_explicit("a\nb", RuntimeWarning, "x.py", 1)
        assert stream.getvalue() == "worker: warning: a b\n"
    assert warnings.showwarning is before
