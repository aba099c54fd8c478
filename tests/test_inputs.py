"""The input rules of :mod:`fkn_bench.inputs`, and that the three entry points share them (issue 34,
finding 7): ``AstrobeeTumble-v0``'s ``step``, the vector environment's ``step`` and the estimator
API's online ``step`` accept and refuse the same kinds of numbers, with the same words; the two
environments' ``reset`` the same seeds."""

from __future__ import annotations

import re
import warnings
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import fkn_bench  # noqa: F401  (registers the environment)
from fkn_bench.envs.astrobee_tumble_vector import AstrobeeTumbleVectorEnv
from fkn_bench.estimators import make_estimator
from fkn_bench.inputs import SEED_LIMIT, check_count, check_seed, describe, real_array, real_number

LONG_DOUBLE_EXCEEDS_FLOAT64 = np.finfo(np.longdouble).maxexp > np.finfo(np.float64).maxexp


# ---------------------------------------------------------------------------- the rules themselves
def test_real_array_converts_real_dtypes_and_passes_float64_through() -> None:
    same = np.arange(7.0)
    assert real_array(same, "x", (7,)) is same
    for value in (np.arange(7), np.arange(7, dtype=np.uint8), np.arange(7, dtype=np.float32), list(range(7)),
                  np.arange(7.0).astype(object), np.arange(7.0).astype(">f8")):
        out = real_array(value, "x", (7,))
        assert out.dtype == np.float64
        np.testing.assert_array_equal(out, np.arange(7.0))
    np.testing.assert_array_equal(real_array([np.inf, np.nan], "x"), [np.inf, np.nan])  # the caller's rule


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (["1.0", "2.0"], r"^x must be a float array of shape \(2,\) \(a real integer or floating dtype; got dtype <U3\)$"),
        ([True, False], r"got dtype bool\)$"),
        (np.array([1 + 2j, 0]), r"got dtype complex128\)$"),
        (np.array(["2020-01-01", "2020-01-02"], dtype="datetime64[D]"), r"got dtype datetime64\[D\]\)$"),
        (np.array([1.0, "a"], dtype=object), r"got dtype object holding str 'a' at x\[1\]\)$"),
        (np.array([1.0, None], dtype=object), r"holding NoneType None at x\[1\]"),
        ([1.0, 10**400], r"^x\[1\] is an integer of 401 digits, beyond float64's range \(\+-1\.8e308\)$"),
        ([1.0, [2.0]], r"^x must be a float array of shape \(2,\) \(got a ragged nesting: \[1\.0, \[2\.0\]\]\)$"),
        (np.zeros((1, 2)), r"^x must have shape \(2,\) \(got \(1, 2\)\)$"),
        (np.float64(1.0), r"^x must have shape \(2,\) \(got \(\)\)$"),
    ],
)
def test_real_array_refuses_by_name(value: Any, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        real_array(value, "x", (2,))


@pytest.mark.skipif(not LONG_DOUBLE_EXCEEDS_FLOAT64, reason="long double is float64 on this platform")
def test_real_array_refuses_a_long_double_beyond_float64() -> None:
    with pytest.raises(ValueError, match=r"^x\[1\] is 1e\+400, beyond float64's range"):
        real_array(np.array([1, "1e400"], dtype=np.longdouble), "x")


def test_check_seed() -> None:
    assert check_seed(np.int64(3)) == 3 and type(check_seed(np.uint64(3))) is int
    assert check_seed(SEED_LIMIT - 1) == SEED_LIMIT - 1
    for bad, words in ((-1, "non-negative integer"), (True, "non-negative integer"), (1.0, "non-negative integer"),
                       (np.array(3), "non-negative integer"), ("3", "non-negative integer"), (SEED_LIMIT, "below 2\\*\\*63")):
        with pytest.raises(ValueError, match=rf"^episode seed must be (a )?{words}"):
            check_seed(bad, "episode seed")
    assert describe(10**400) == "an integer of 401 digits" and describe("x" * 100).endswith("...")


def test_real_number_and_check_count() -> None:
    for value in (2, 2.0, np.float32(2.0), np.int64(2), np.array(2.0), np.array(2, dtype=np.uint8)):
        assert real_number(value, "dt") == 2.0
    assert np.isnan(real_number(np.nan, "dt"))  # the caller's rule
    for bad in (True, np.bool_(False), "0.1", 0.1 + 0j, [0.1], np.array([0.1]), None):
        with pytest.raises(ValueError, match=r"^dt must be a number \(got "):
            real_number(bad, "dt", "a number")
    with pytest.raises(ValueError, match=r"^dt is an integer of 401 digits, beyond float64's range"):
        real_number(10**400, "dt")
    assert check_count(np.int64(4), "num_envs") == 4
    for bad in (0, -1, 2.0, True, "5", None):
        with pytest.raises(ValueError, match=r"^num_envs must be an integer >= 1 \(got "):
            check_count(bad, "num_envs")


# ---------------------------------------------------------------------------- one rule, three entry points
@pytest.fixture(scope="module")
def entry_points() -> dict[str, Callable[[Callable[[int], Any]], Any]]:
    """``{name: call(make)}``: ``call`` feeds ``make(n)`` (a vector of ``n`` numbers, the entry
    point's length) to the entry point, batched for the vector environment."""
    single = gym.make("AstrobeeTumble-v0", n_steps=20)
    vector = AstrobeeTumbleVectorEnv(num_envs=2, n_steps=20)
    estimator = make_estimator("manual-ekf")

    def single_step(make: Callable[[int], Any]) -> Any:
        single.reset(seed=0)
        return single.step(make(13))

    def vector_step(make: Callable[[int], Any]) -> Any:
        vector.reset(seed=0)
        row = make(13)
        if isinstance(row, np.ndarray):  # (a 0-d array goes as it is: the wrong shape for both)
            return vector.step(np.stack([row, row]) if row.ndim else row)
        return vector.step([row, row])

    def estimator_step(make: Callable[[int], Any]) -> Any:
        estimator.reset(dt=0.1)
        return estimator.step({"pose": make(7), "valid": 1, "time": 0.0})

    return {"single env step": single_step, "vector env step": vector_step, "estimator step": estimator_step}


def _unit(n: int) -> np.ndarray:
    return np.eye(1, n)[0]  # [1, 0, ...]: an identity quaternion, zeros elsewhere


REFUSED: dict[str, tuple[Callable[[int], Any], str]] = {
    "numeric strings": (lambda n: _unit(n).astype(str), r"must be a float array of shape .*got dtype <U32\)"),
    "a string in a list": (lambda n: ["1.0"] + [0.0] * (n - 1), r"must be a float array of shape .*got dtype <U32\)"),
    "bools": (lambda n: _unit(n).astype(bool), r"must be a float array of shape .*got dtype bool\)"),
    "complex": (lambda n: _unit(n).astype(complex), r"must be a float array of shape .*got dtype complex128\)"),
    "objects": (lambda n: np.array([object()] * n), r"got dtype object holding object"),
    "10**400": (lambda n: [10**400] + [0] * (n - 1), r"\[0(, 0)?\] is an integer of 401 digits, beyond float64's range"),
    "a 0-d array": (lambda n: np.array(1.0), r"must have shape \((2, 13|13,|7,)\) \(got \(\)\)"),
    "an extra axis": (lambda n: _unit(n)[None], r"must have shape \((2, 13|13,|7,)\) \(got \((2, )?1, (13|7)\)\)"),
    "a ragged nesting": (lambda n: [1.0, [0.0] * (n - 1)], r"must be a float array of shape .*\(got a ragged nesting"),
}
ACCEPTED: dict[str, Callable[[int], Any]] = {
    "int64": lambda n: _unit(n).astype(np.int64),
    "uint8": lambda n: _unit(n).astype(np.uint8),
    "float32": lambda n: _unit(n).astype(np.float32),
    "a list of floats": lambda n: _unit(n).tolist(),
    "an object array of numbers": lambda n: _unit(n).astype(object),
}


@pytest.mark.parametrize("kind", list(REFUSED))
def test_same_refusal_in_all_three_entry_points(entry_points: dict, kind: str) -> None:
    make, pattern = REFUSED[kind]
    messages = []
    for name, call in entry_points.items():
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # e.g. no ComplexWarning on the way to the error
            with pytest.raises(ValueError, match=pattern) as caught:
                call(make)
        message = str(caught.value)
        assert "\n" not in message, f"{name}: not one line"
        messages.append(_normalised(message))
    assert len(set(messages)) == 1, f"the entry points word the same rule differently: {messages}"


def _normalised(message: str) -> str:
    """``message`` with what differs between the entry points by design replaced: the name
    (``action``, ``observation 'pose'``), the expected shape, the batch index and axis, object
    addresses and the echoed input."""
    for pattern, replacement in (
        (r"observation 'pose'|action|pose", "NAME"),
        (r"\(2, 13\)|\(13,\)|\(7,\)", "SHAPE"),
        (r"\(got \((2, )?1, (13|7)\)\)", "(got EXTRA AXIS)"),
        (r"\[0, (\d+)\]", r"[\1]"),
        (r" at 0x[0-9a-f]+", ""),
        (r"ragged nesting: .*", "ragged nesting"),
    ):
        message = re.sub(pattern, replacement, message)
    return message


@pytest.mark.parametrize("kind", list(ACCEPTED))
def test_same_acceptance_in_all_three_entry_points(entry_points: dict, kind: str) -> None:
    for call in entry_points.values():
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            call(ACCEPTED[kind])


SEEDS_REFUSED = [2**70, 2**64, SEED_LIMIT, -1, 1.5, float("nan"), float("inf"), True, np.bool_(True), "3",
                 np.array(3), np.float64(2.0), None.__class__]
SEEDS_ACCEPTED = [0, np.int64(3), np.uint32(5), SEED_LIMIT - 2]


@pytest.mark.parametrize("seed", SEEDS_REFUSED, ids=repr)
def test_same_seed_refusal_in_both_environments(seed: Any) -> None:
    single = gym.make("AstrobeeTumble-v0", n_steps=20)
    vector = AstrobeeTumbleVectorEnv(num_envs=2, n_steps=20)
    with pytest.raises(ValueError) as from_single:
        single.reset(seed=seed)
    with pytest.raises(ValueError) as from_vector:
        vector.reset(seed=seed)
    assert str(from_single.value) == str(from_vector.value)
    assert str(from_single.value).startswith("seed must be ")


@pytest.mark.parametrize("seed", SEEDS_ACCEPTED, ids=repr)
def test_same_seed_acceptance_in_both_environments(seed: Any) -> None:
    single = gym.make("AstrobeeTumble-v0", n_steps=20)
    vector = AstrobeeTumbleVectorEnv(num_envs=2, n_steps=20)
    observation, info = single.reset(seed=seed)
    batch, batch_info = vector.reset(seed=seed)
    assert info["episode_seed"] == batch_info["episode_seed"][0] == int(seed)
    np.testing.assert_array_equal(observation["pose"], batch["pose"][0])
