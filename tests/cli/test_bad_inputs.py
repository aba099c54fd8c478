"""No user error ends in a traceback: every command, given bad input, exits with status 2 and one
readable line (argparse's own errors: its usage, then one error line), and Ctrl-C, start-up
included, exits with 130 and one line (issue 19, item 7); option errors name the option, the key
and what is valid (issue 20, item 2)."""

from __future__ import annotations

import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fkn_bench.cli import main

BAD_INPUTS = [
    ("run --estimator nope", "unknown estimator 'nope'; valid estimators: manual-ekf"),
    ("run --scenario nope", "unknown scenario 'nope'; valid scenarios: ds1"),
    ("run --seeds 0", "--seeds must be a positive integer (got 0)"),
    ("run --out afile --seeds 1 --estimator manual-ekf", "--out: afile is a file, not a directory"),
    ("run --estimator flexkalmannet --estimator-option parameters=nope.json --seeds 1",
     "--estimator-option parameters=nope.json: learned-parameter file not found: nope.json"),
    ("run --estimator manual-ekf --estimator-option foo=bar --seeds 1",
     "--estimator-option foo=bar: estimator 'manual-ekf' has no option 'foo'; valid options: description, gate, inertia,"),
    ("run --estimator sage-husa --estimator-option alpha=3 --scenario ds1 --seeds 1",
     "--estimator-option alpha=3: unknown SageHusaEstimator options ['alpha']; valid: ['adapt', 'adapt_q',"),
    ("run --estimator flexkalmannet --estimator-option parameters= --seeds 1", "the learned-parameter file name is empty"),
    ("run --recording nope.mcap --estimator manual-ekf", "recording not found: nope.mcap"),
    ("run --recording afile --estimator manual-ekf", "afile: not an MCAP file"),
    ("run --scenario-file nope.toml", "scenario file not found: nope.toml"),
    ("run --scenario-file latin1.toml", "scenario file latin1.toml is not UTF-8 text"),
    ("run --cut -5 --seeds 1 --estimator manual-ekf", "--cut must be a non-negative integer (got -5)"),
    ("run --dataset nope --estimator manual-ekf", "dataset not found: nope"),
    ("run --dataset afile --scenario ds1", "--dataset replaces --scenario, --all and --recording"),
    ("dataset --out afile --seeds 1", "--out: afile is a file, not a directory"),
    ("dataset --out d --seeds 1 --estimator nope", "unknown estimator 'nope'"),
    ("run --seeds abc", "argument --seeds: invalid int value: 'abc'"),
    ("train --estimator nope", "unknown estimator 'nope'"),
    ("train --estimator flexkalmannet --out afile", "--out: afile is a file, not a directory"),
    ("train --set hiddn=64 --estimator flexkalmannet --out t", "unknown FlexKalmanNet config keys ['hiddn']; valid:"),
    ("train --set hidden=abc --estimator flexkalmannet --out t", "FlexKalmanNet config key 'hidden' must be an integer (got 'abc')"),
    ("train --epochs 0 --estimator flexkalmannet --out t", "--epochs must be a positive integer (got 0)"),
    ("train --lr -1 --estimator flexkalmannet --out t", "--lr must be a finite number > 0 (got -1)"),
    ("train --seeds 0 1 --seed 3 --out t", "give either --seed or --seeds, not both"),
    ("train --seeds 0 0 --out t", "--seeds must be distinct integers >= 0 (got 0 0)"),
    ("train --seeds 1 2 --set hiddn=64 --out t", "unknown FlexKalmanNet config keys ['hiddn']; valid:"),
    ("sweep --space seeds --scenario spin --write-artifact --out t",
     "a seed study of flexkalmannet installs its median-validation seed through training: fkn-bench train "
     "--estimator flexkalmannet --scenario spin --seeds 0 1 2 --write-artifact"),
    ("train --device gpu --estimator flexkalmannet --out t", "unknown device 'gpu': use cpu, cuda or cuda:N"),
    ("train --device cuda:7 --estimator flexkalmannet --out t", "device 'cuda:7' asked for, but "),
    ("bench train --device cuda:7", "device 'cuda:7' asked for, but "),
    ("bench run --device gpu", "unknown device 'gpu': use cpu, cuda or cuda:N"),
    ("record --scenario nope --out r.mcap", "unknown scenario 'nope'"),
    ("record --out /proc/fkn-bench/r.mcap --steps 10", "cannot write /proc/fkn-bench/r.mcap: "),  # (not even root may)
    ("reproduce --out afile", "--out: afile is a file, not a directory"),
    ("sweep --space nope --out s", "search-space file not found: nope"),
    ("sweep --space latin1.toml --out s", "search-space file latin1.toml is not UTF-8 text"),
    ("sweep --space quick --trials 0 --out s", "--trials must be a positive integer (got 0)"),
    ("sweep --space quick --workers 0 --out s", "--workers must be a positive integer (got 0)"),
    ("simulate --scenario nope", "unknown scenario 'nope'"),
    ("render --out frame.txt", "--out must end in .png, .gif, .mp4 (got frame.txt)"),
    ("render --estimator nope --out f.png", "unknown estimator 'nope'"),
    ("plot --results nope", "results directory not found: nope"),
    ("leaderboard --results nope", "results directory not found: nope"),
]


@pytest.mark.parametrize(("command", "message"), BAD_INPUTS, ids=[c for c, _ in BAD_INPUTS])
def test_bad_input_exits_2_with_one_readable_line(command: str, message: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "afile").write_text("x\n")
    (tmp_path / "latin1.toml").write_bytes("name = 'caf\xe9'\n".encode("latin-1"))
    with pytest.raises(SystemExit) if message.startswith("argument ") else _no_exit() as exited:
        code = main(shlex.split(command))
    code = exited.value.code if exited is not None else code
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and "Traceback" not in err
    name = command.split()[0]
    assert lines[-1].startswith(f"fkn-bench {name}: error: ") and message in lines[-1], lines
    if not message.startswith("argument "):
        assert len(lines) == 1, lines
    assert "weights_only" not in err


class _no_exit:
    """``pytest.raises``' counterpart for commands that return their status (``value`` None)."""

    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> bool:
        return False


CONSOLE_SCRIPT = shutil.which("fkn-bench")
needs_the_console_script = pytest.mark.skipif(CONSOLE_SCRIPT is None or sys.platform == "win32",
                                              reason="needs the console script (POSIX signals)")


def _started(argv: list[str], cwd: Path) -> subprocess.Popen:
    # SIGINT back to its default in the child: a test run started in the background (`cmd &` in
    # a non-interactive shell, as CI may) inherits it ignored, and Python then never raises
    # KeyboardInterrupt
    return subprocess.Popen(argv, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def _interrupted(process: subprocess.Popen) -> list[str]:
    """The stderr lines of an interrupted command, checked for status 130 and no traceback."""
    _, err = process.communicate(timeout=120)
    assert process.returncode == 130 and "Traceback" not in err, (process.returncode, err)
    return [line for line in err.splitlines() if line.strip()]


@needs_the_console_script
def test_ctrl_c_at_start_up_exits_130_in_one_line(tmp_path: Path) -> None:
    """SIGINT while the command's modules load (the package imported, ``main`` not yet running):
    the child sends it to itself at that point, as the console script would run it (its name
    ``fkn-bench``), so that the moment does not depend on the machine's speed or load (a timer in
    the parent lands earlier than the package's handler on a loaded machine, and after start-up on
    a fast one)."""
    code = (f"import os, signal, sys; sys.argv = [{CONSOLE_SCRIPT!r}, 'run', '--seeds', '2', '--no-progress']; "
            "import fkn_bench; os.kill(os.getpid(), signal.SIGINT); "
            "from fkn_bench.cli import main; sys.exit(main())")
    assert _interrupted(_started([sys.executable, "-c", code], tmp_path)) == ["fkn-bench: interrupted"]


def test_ctrl_c_while_the_parser_is_built_exits_130_in_one_line(monkeypatch: pytest.MonkeyPatch,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """SIGINT after ``main`` took over, before a command runs (its modules import, the parser is
    built): Python's KeyboardInterrupt, one line."""
    from fkn_bench import cli

    def interrupted() -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "build_parser", interrupted)
    assert main(["run", "--seeds", "2"]) == 130
    assert capsys.readouterr().err == "fkn-bench: interrupted\n"


@needs_the_console_script
def test_ctrl_c_while_running_exits_130_in_one_line(tmp_path: Path) -> None:
    """SIGINT while ``fkn-bench run`` computes its cells: sent as soon as the results directory is
    marked (the run has started; its cells take seconds), not after a fixed delay."""
    from fkn_bench.harness.store import MARKER

    scenarios = [arg for name in ("ds1", "ds2", "ds1-noise5x", "ds1-gap100", "ds1-flips", "tumble-fast")
                 for arg in ("--scenario", name)]
    process = _started([CONSOLE_SCRIPT, "run", "--estimator", "manual-ekf", *scenarios, "--seeds", "20", "--no-progress",
                        "--out", "out"], tmp_path)
    try:
        deadline = time.monotonic() + 120
        while not (tmp_path / "out" / MARKER).is_file() and process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.005)
        assert process.poll() is None, f"the run ended before it was interrupted: {process.communicate()}"
        assert (tmp_path / "out" / MARKER).is_file(), "the run did not start within 120 s"
        process.send_signal(signal.SIGINT)
        assert _interrupted(process) == ["fkn-bench run: interrupted; the finished cells are saved in out: run the same "
                                         "command again to resume"]
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()


def test_sigterm_ends_a_command_as_ctrl_c_does() -> None:
    """`kill` (SIGTERM) raises KeyboardInterrupt inside a command, so that a run stops its worker
    processes and says what it saved (killed outright, its pool workers were left orphaned)."""
    from fkn_bench import cli

    before = signal.getsignal(signal.SIGTERM)
    if before is not signal.SIG_DFL:
        pytest.skip("SIGTERM is handled by this test process's host")
    try:
        assert cli._handle_sigterm() is signal.SIG_DFL and signal.getsignal(signal.SIGTERM) is cli._terminated
        with pytest.raises(KeyboardInterrupt, match="terminated"):
            cli._terminated(signal.SIGTERM, None)
        assert cli._handle_sigterm() is None  # already handled: left alone
    finally:
        signal.signal(signal.SIGTERM, before)
    assert main(["scenarios"]) == 0 and signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # restored after a command


@pytest.mark.parametrize("command", ["run", "record", "train", "reproduce", "sweep"])
def test_warnings_reach_the_user_as_one_line_each(command: str, monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """A warning raised while a command runs is one line, ``fkn-bench CMD: warning: ...`` (no
    file name, line number or source line), and messages spell options as flags."""
    import importlib
    import warnings

    from fkn_bench.wording import option

    def handler(args: object) -> int:
        warnings.warn("first line\n  second line", UserWarning)
        warnings.warn(f"pass {option('repair')}", DeprecationWarning)
        return 0

    monkeypatch.setattr(importlib.import_module(f"fkn_bench.cli.{command}"), "run", handler)
    arguments = {"sweep": ["--space", "quick"], "record": ["--out", "r.mcap"]}.get(command, [])
    assert main([command, *arguments]) == 0
    lines = capsys.readouterr().err.splitlines()
    assert lines == [f"fkn-bench {command}: warning: first line second line",
                     f"fkn-bench {command}: warning (DeprecationWarning): pass --repair"]
    assert option("repair") == "repair=True"  # outside a command: the Python spelling
