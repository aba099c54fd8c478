"""The speed-ratio gate (:mod:`fkn_bench.gates.speed`): what does not depend on time.

The timed verdicts (the real code passes every check, and each hotspot made to do its work twice
fails) are a benchmark, not a test: the test command runs them after pytest as
``fkn-bench bench gate --trips``, on a machine with nothing else to do (as timed tests inside the
suite they failed at random whenever another process loaded the machine). Here: the thresholds
against the measured ratios, the reference's numbers, :func:`~fkn_bench.gates.speed.doubled`, and
the command's wiring and exit codes with the timing replaced by fixed ratios.
"""

from __future__ import annotations

import pytest

from fkn_bench.gates import speed


def test_doubled_restores_the_original() -> None:
    from fkn_bench.filters.ekf import ExtendedKalmanFilter
    from fkn_bench.filters.base import KalmanFilter

    assert "run" not in vars(ExtendedKalmanFilter)  # inherited: shadowed, then removed again
    with speed.doubled("fkn_bench.filters.ekf:ExtendedKalmanFilter.run"):
        assert "run" in vars(ExtendedKalmanFilter)
    assert "run" not in vars(ExtendedKalmanFilter)
    assert ExtendedKalmanFilter.run is KalmanFilter.run


def test_numpy_reference_matches_the_batched_filter() -> None:
    """The reference does the same work as the candidate: same numbers, to rounding."""
    import numpy as np
    import torch

    from fkn_bench.filters import make_filter

    z, m, dt = speed.episodes_for("ds1", 4, 120)
    noise = speed.manual_noise("ekf")
    reference = speed.numpy_ekf_loop(z, m, *(t.numpy() for t in (noise.process, noise.measurement, noise.initial)), dt)
    with torch.no_grad():
        batched = make_filter("ekf").run(noise, torch.from_numpy(np.array(z)), torch.from_numpy(np.array(m)), dt=dt)
    initialised = batched.initialised.numpy()
    np.testing.assert_allclose(reference[initialised], batched.means.numpy()[initialised], rtol=0, atol=1e-10)


def test_thresholds_separate_the_measured_ratios() -> None:
    """Each threshold lies below every ratio measured for the real code and above every ratio
    measured with the work doubled (:data:`~fkn_bench.gates.speed.MEASURED`)."""
    for check in speed.gated_checks(speed.all_checks()):
        measured = speed.MEASURED.get(check.name)
        assert measured is not None, f"{check.name}: record its measured ratios in speed.MEASURED"
        assert measured["doubled_max"] < check.min_ratio < measured["min"], check.name


def test_every_hotspot_is_tripped_once() -> None:
    """``--trips`` doubles each gated hotspot once (through its first gated check); the online
    steps with the budget only are not tripped (a 2x slowdown stays within their budget)."""
    checks = speed.all_checks()
    tripped = speed.trip_checks(checks)
    assert sorted(c.hotspot for c in tripped) == sorted({c.hotspot for c in speed.gated_checks(checks)})
    assert "online-step:manual-ekf" in {c.name for c in tripped} and "ekf-forward" in {c.name for c in tripped}
    assert not any(c.min_ratio == speed.DEFAULT_ONLINE_STEP_MIN_RATIO for c in tripped)


def _fake_gate(monkeypatch: pytest.MonkeyPatch, real: dict[str, float], halved_by_doubling: bool = True) -> None:
    """The gate's checks replaced by three without work, whose measured ratio is ``real[name]``
    and half of it (or, with ``halved_by_doubling=False``, the same) while their hotspot is
    doubled: the command's logic without timings."""
    from contextlib import contextmanager

    state = {"doubled": False}

    @contextmanager
    def doubled(hotspot: str, combine: object = None):  # noqa: ANN202
        state["doubled"] = True
        try:
            yield
        finally:
            state["doubled"] = False

    def measure_ratio(check: speed.RatioCheck, **_: object) -> speed.RatioMeasurement:
        ratio = real[check.name] / (2.0 if state["doubled"] and halved_by_doubling else 1.0)
        return speed.RatioMeasurement(check.name, 1.0, 1.0 / ratio, (ratio,))

    def nothing() -> speed.Workloads:
        return speed.Workloads(lambda: None, lambda: None)

    checks = [speed.RatioCheck("fake-forward", "a", nothing, min_ratio=1.0, hotspot="m:f"),
              speed.RatioCheck("fake-backward", "b", nothing, min_ratio=0.5, hotspot="m:f"),
              speed.RatioCheck("online-step:fake", "c", nothing, min_ratio=0.01, hotspot="m:g")]
    monkeypatch.setattr(speed, "all_checks", lambda: checks)
    monkeypatch.setattr(speed, "doubled", doubled)
    monkeypatch.setattr(speed, "measure_ratio", measure_ratio)


def test_the_gate_command_passes_real_code_and_trips_doubled_code(monkeypatch: pytest.MonkeyPatch,
                                                                  capsys: pytest.CaptureFixture) -> None:
    import json

    from fkn_bench.cli import main

    _fake_gate(monkeypatch, {"fake-forward": 1.5, "fake-backward": 0.8, "online-step:fake": 0.4})
    assert main(["bench", "gate", "--trips"]) == 0
    out = capsys.readouterr().out
    assert "fake-forward" in out and "tripped, as it should" in out and "DOUBLED PASSED" not in out
    assert main(["bench", "gate", "--trips", "--json"]) == 0
    document = json.loads(capsys.readouterr().out)
    assert [c["check"] for c in document["doubled"]] == ["fake-forward"]  # one per hotspot, gated only
    assert len(document["checks"]) == 3


def test_the_gate_command_fails_a_slow_check_or_a_gate_that_misses_a_doubling(monkeypatch: pytest.MonkeyPatch,
                                                                              capsys: pytest.CaptureFixture) -> None:
    from fkn_bench.cli import main

    _fake_gate(monkeypatch, {"fake-forward": 0.9, "fake-backward": 0.8, "online-step:fake": 0.4})
    assert main(["bench", "gate", "--attempts", "2"]) == 1  # below 1.0 on every attempt
    assert "TOO SLOW" in capsys.readouterr().out
    _fake_gate(monkeypatch, {"fake-forward": 1.5, "fake-backward": 0.8, "online-step:fake": 0.4}, halved_by_doubling=False)
    assert main(["bench", "gate", "--trips"]) == 1
    assert "DOUBLED PASSED" in capsys.readouterr().out


def test_gate_calibration_prints_ratios_and_a_threshold(monkeypatch: pytest.MonkeyPatch,
                                                        capsys: pytest.CaptureFixture) -> None:
    """``fkn-bench bench gate --calibrate``: the measured and doubled ratios, and 0.7 of the
    median as the suggested threshold."""
    import json

    from fkn_bench.cli import main

    _fake_gate(monkeypatch, {"fake-forward": 1.5, "fake-backward": 0.8, "online-step:fake": 0.4})
    assert main(["bench", "gate", "--check", "fake-forward", "--calibrate", "2", "--json"]) == 0
    entry = json.loads(capsys.readouterr().out)["fake-forward"]
    assert entry["n"] == 2 and entry["median"] == 1.5 and entry["doubled_max"] == 0.75
    assert entry["suggested_min_ratio"] == 1.0  # 0.7 x 1.5 to two digits


def test_a_non_causal_estimator_has_no_online_step_to_time() -> None:
    from fkn_bench.gates.speed import estimator_checks, online_step_check

    with pytest.raises(ValueError, match="non-causal"):
        online_step_check("smoother-matched")
    assert "online-step:oracle-matched" in [c.name for c in estimator_checks(["oracle-matched", "smoother-matched"])]
