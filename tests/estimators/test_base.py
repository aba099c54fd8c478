"""The estimator API base: input checks, observation parsing, immutable estimates, and the
saved-estimator document (format, version, class, atomic writes)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fkn_bench.estimators import (
    Estimate,
    Estimates,
    Estimator,
    EstimatorFileError,
    check_batch_inputs,
    load_estimator,
    parse_observation,
)
from fkn_bench.estimators.base import ESTIMATOR_FORMAT, ESTIMATOR_FORMAT_VERSION, read_estimator_document
from fkn_bench.filters.pose import error_covariance_from_state, state_covariance_from_error


class Hold(Estimator):
    """A minimal estimator: reports the last measurement (module level, so it can be loaded)."""

    name = "hold"

    def __init__(self, *, gain: float = 1.0) -> None:
        self.gain = float(gain)
        self._last = np.array([1.0] + [0.0] * 12)

    def estimate(self, measurements, mask, dt):  # noqa: ANN001, ANN201
        z, m, _ = check_batch_inputs(measurements, mask, dt)
        return Estimates(means=np.zeros(z.shape[:2] + (13,)))

    def reset(self, *, dt: float) -> None:
        self._last = np.array([1.0] + [0.0] * 12)

    def step(self, observation: Any) -> Estimate:
        pose, time = parse_observation(observation)
        if pose is not None:
            self._last = np.concatenate((pose, np.zeros(6)))
        return Estimate(time=time or 0.0, mean=self._last.copy(), native_covariance=np.eye(13), initialised=True, updated=pose is not None)

    def to_config(self) -> dict[str, Any]:
        return {"gain": self.gain}


# ---------------------------------------------------------------------------- check_batch_inputs
def test_check_batch_inputs_accepts_and_converts() -> None:
    z = np.zeros((2, 3, 7), dtype=np.float32)
    z[:, 1] = np.nan  # anything goes outside (and inside) the mask
    out, mask, dt = check_batch_inputs(z.tolist(), [[1, 0, 1], [0, 0, 1]], np.float32(0.1))
    assert out.dtype == np.float64 and out.shape == (2, 3, 7)
    assert mask.dtype == np.bool_ and mask.tolist() == [[True, False, True], [False, False, True]]
    assert isinstance(dt, float) and dt == pytest.approx(0.1)


@pytest.mark.parametrize(
    ("measurements", "mask", "dt", "message"),
    [
        (np.zeros((3, 7)), np.ones(3, bool), 0.1, r"\(B, T, 7\) \(got \(3, 7\)\) \(use measurements\[None\] for a single sequence\)"),
        (np.zeros((1, 3, 6)), np.ones((1, 3), bool), 0.1, r"must have shape \(B, T, 7\) \(got \(1, 3, 6\)\)"),
        (np.zeros((0, 3, 7)), np.ones((0, 3), bool), 0.1, "no sequences or no time steps"),
        (np.zeros((1, 0, 7)), np.ones((1, 0), bool), 0.1, "no sequences or no time steps"),
        (np.zeros((1, 3, 7)), np.ones((1, 4), bool), 0.1, r"mask must have shape \(1, 3\)"),
        (np.zeros((1, 3, 7)), np.full((1, 3), 2), 0.1, "mask must be boolean"),
        ([["a"] * 7], np.ones((1, 1), bool), 0.1, "measurements must be a float array"),
        (np.zeros((1, 3, 7)), np.ones((1, 3), bool), 0.0, "dt must be a finite number > 0"),
        (np.zeros((1, 3, 7)), np.ones((1, 3), bool), -1.0, "dt must be a finite number > 0"),
        (np.zeros((1, 3, 7)), np.ones((1, 3), bool), math.nan, "dt must be a finite number > 0"),
        (np.zeros((1, 3, 7)), np.ones((1, 3), bool), math.inf, "dt must be a finite number > 0"),
        (np.zeros((1, 3, 7)), np.ones((1, 3), bool), "0.1s", "dt must be a number"),
        (np.zeros((1, 3, 7)), np.ones((1, 3), bool), None, "dt must be a number"),
    ],
)
def test_check_batch_inputs_refuses(measurements, mask, dt, message: str) -> None:  # noqa: ANN001
    with pytest.raises(ValueError, match=message):
        check_batch_inputs(measurements, mask, dt)


# ---------------------------------------------------------------------------- parse_observation
def test_parse_observation_forms() -> None:
    pose = np.arange(7.0)
    got, time = parse_observation({"pose": pose, "valid": np.int64(1), "time": np.array(2.5)})
    np.testing.assert_array_equal(got, pose)  # exact: copied
    assert time == 2.5 and isinstance(time, float)
    assert parse_observation({"pose": pose, "valid": 0, "time": 1.0}) == (None, 1.0)  # invalid flag wins
    assert parse_observation({"pose": np.full(7, np.nan), "time": 3.0}) == (None, 3.0)
    got, time = parse_observation({"pose": pose})
    assert time is None and got is not None
    assert parse_observation(np.full(7, np.nan)) == (None, None)
    partial = pose.copy()
    partial[3] = np.nan  # partly NaN: returned; the filters skip it by their rule
    got, _ = parse_observation(partial.tolist())
    assert got is not None and np.isnan(got[3])
    with pytest.raises(ValueError, match=r"observation dict needs a 'pose' entry \(has \['time', 'valid'\]\)"):
        parse_observation({"valid": 1, "time": 0.0})
    with pytest.raises(ValueError, match=r"a pose observation must have shape \(7,\) \(got \(13,\)\)"):
        parse_observation(np.zeros(13))
    with pytest.raises(ValueError, match=r"shape \(7,\) \(got \(1, 7\)\)"):
        parse_observation({"pose": np.zeros((1, 7))})


# ---------------------------------------------------------------------------- Estimate / Estimates
def test_estimate_is_immutable_and_converts_covariances() -> None:
    rng = np.random.default_rng(0)
    q = rng.standard_normal(4)
    q /= np.linalg.norm(q)
    mean = np.concatenate((q, rng.standard_normal(9)))
    L = rng.standard_normal((12, 12))
    error = L @ L.T
    additive = Estimate(time=1.0, mean=mean.copy(), native_covariance=state_covariance_from_error(q, error), initialised=True, updated=True)
    for array in (additive.mean, additive.native_covariance):
        with pytest.raises(ValueError, match="read-only"):
            array[0] = 1.0
    with pytest.raises(AttributeError):
        additive.time = 2.0  # type: ignore[misc]
    assert additive.covariance is additive.native_covariance
    np.testing.assert_allclose(additive.error_covariance, error, rtol=0, atol=1e-12)
    # exact (this and the next): the property calls this very function on the same q and matrix
    np.testing.assert_allclose(additive.error_covariance, error_covariance_from_state(q, additive.native_covariance), rtol=0, atol=0)
    multiplicative = Estimate(time=1.0, mean=mean.copy(), native_covariance=error.copy(), initialised=True, updated=False)
    assert multiplicative.error_covariance is multiplicative.native_covariance
    np.testing.assert_allclose(multiplicative.covariance, state_covariance_from_error(q, error), rtol=0, atol=0)
    assert multiplicative.covariance is multiplicative.covariance  # converted once


def test_estimates_sizes() -> None:
    estimates = Estimates(means=np.zeros((3, 5, 13)))
    assert (estimates.batch_size, estimates.n_steps) == (3, 5)
    assert estimates.covariances is None and dict(estimates.extras) == {}


# ---------------------------------------------------------------------------- saved documents
def test_save_writes_the_documented_document_and_load_round_trips(tmp_path: Path) -> None:
    path = Hold(gain=2.5).save(tmp_path / "sub" / "hold.json")
    document = json.loads(path.read_text())
    assert document == {
        "format": ESTIMATOR_FORMAT,
        "format_version": ESTIMATOR_FORMAT_VERSION,
        "name": "hold",
        "class": f"{__name__}:Hold",
        "config": {"gain": 2.5},
    }
    loaded = load_estimator(path)
    assert type(loaded).__name__ == "Hold" and loaded.gain == 2.5  # type: ignore[attr-defined]
    assert Hold.load(path).gain == 2.5  # type: ignore[attr-defined]
    assert sorted(p.name for p in (tmp_path / "sub").iterdir()) == ["hold.json"]  # no temp files left
    assert repr(loaded) == "Hold(name='hold')"


def test_failed_save_leaves_the_old_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = Hold(gain=1.0).save(tmp_path / "hold.json")
    before = path.read_bytes()

    def broken(self: Hold) -> dict[str, Any]:
        raise RuntimeError("config unavailable")

    monkeypatch.setattr(Hold, "to_config", broken)
    with pytest.raises(RuntimeError, match="config unavailable"):
        Hold(gain=9.0).save(path)
    monkeypatch.setattr(Hold, "to_config", lambda self: {"gain": object()})  # not serialisable
    with pytest.raises(TypeError, match="cannot convert object to JSON"):
        Hold(gain=9.0).save(path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hold.json"]


def _write(path: Path, document: Any) -> Path:
    path.write_text(json.dumps(document) if not isinstance(document, str) else document)
    return path


def test_loading_refuses_bad_files(tmp_path: Path) -> None:
    good = json.loads(Hold().save(tmp_path / "good.json").read_text())
    cases = [
        ("missing.json", None, r"cannot read estimator file .*missing\.json: file not found"),
        ("corrupt.json", '{"format": "fkn-bench-estimator", ', r"cannot read estimator file .*corrupt\.json: .* is not valid JSON"),
        ("binary.json", None, r"is not UTF-8 text"),
        ("list.json", [1, 2], r"list\.json is not an fkn-bench estimator file \(no format 'fkn-bench-estimator'\)"),
        ("format.json", {**good, "format": "other"}, r"format\.json is not an fkn-bench estimator file"),
        ("version.json", {**good, "format_version": 99}, r"has estimator format version 99; this fkn-bench reads version 1"),
        ("noversion.json", {k: v for k, v in good.items() if k != "format_version"}, r"format version None; this fkn-bench reads version 1"),
        ("noconfig.json", {k: v for k, v in good.items() if k != "config"}, r"lacks the estimator 'name' or 'config'"),
        ("noclass.json", {k: v for k, v in good.items() if k != "class"}, r"does not record the estimator class"),
        ("unimportable.json", {**good, "class": "no_such_module_xyz:Thing"}, r"cannot import estimator class no_such_module_xyz:Thing"),
        ("noattr.json", {**good, "class": f"{__name__}:Missing"}, r"cannot import estimator class"),
        ("notestimator.json", {**good, "class": "fkn_bench.io:to_jsonable"}, r"fkn_bench\.io:to_jsonable is not an Estimator class"),
        ("badconfig.json", {**good, "config": {"gain": "lots"}}, r"badconfig\.json: invalid Hold config"),
    ]
    for name, document, message in cases:
        path = tmp_path / name
        if name == "binary.json":
            path.write_bytes(b"\xff\xfe\x00garbage")
        elif document is not None:
            _write(path, document)
        with pytest.raises(EstimatorFileError, match=message):
            load_estimator(path)
    # EstimatorFileError is a ValueError: callers may catch either
    assert issubclass(EstimatorFileError, ValueError)


def test_class_load_refuses_another_class(tmp_path: Path) -> None:
    from fkn_bench.estimators import KalmanEstimator

    path = Hold().save(tmp_path / "hold.json")
    with pytest.raises(EstimatorFileError, match=rf"holds a {__name__}:Hold estimator, not a fkn_bench\.estimators\.kalman:KalmanEstimator"):
        KalmanEstimator.load(path)
    # documents without a class entry load through the class named by the caller
    document = json.loads(path.read_text())
    del document["class"]
    assert Hold.load(_write(tmp_path / "plain.json", document)).gain == 1.0  # type: ignore[attr-defined]
    assert read_estimator_document(tmp_path / "plain.json")["name"] == "hold"


@pytest.mark.parametrize("name", ["manual-ekf", "sage-husa"])
@pytest.mark.parametrize("bad_time", [0.1, float("nan"), float("inf")])
def test_a_refused_step_leaves_the_estimator_as_it_was(name: str, bad_time: float) -> None:
    """A time that does not increase, or is not finite, is refused (ValueError) and changes
    nothing: the next valid step gives what it gives without the refused one."""
    from fkn_bench.estimators import make_estimator

    pose = np.array([1.0, 0.0, 0.0, 0.0, 0.1, 0.2, 0.3])
    clean, refused = make_estimator(name), make_estimator(name)
    for estimator in (clean, refused):
        estimator.reset(dt=0.1)
        estimator.step({"pose": pose, "time": 0.1})
        estimator.step({"pose": pose, "time": 0.2})
    with pytest.raises(ValueError, match="does not increase|finite"):
        refused.step({"pose": pose, "time": bad_time})
    expected, got = clean.step({"pose": pose, "time": 0.3}), refused.step({"pose": pose, "time": 0.3})
    np.testing.assert_array_equal(got.mean, expected.mean)  # the same operations on the same inputs
    np.testing.assert_array_equal(got.native_covariance, expected.native_covariance)
