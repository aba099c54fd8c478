"""The one recursion (fkn_bench/filters/recursion.py), on a toy filter whose every step is visible:
a scalar state that averages with each accepted measurement."""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
import pytest

from fkn_bench.filters.recursion import GATE_REINITIALISE_AFTER, Carry, Proposal, advance, first_usable, scan, select


class Scalar(NamedTuple):
    x: np.ndarray  # (B, 1)
    predictions: np.ndarray  # (B,) predictions since the start


class Averaging:
    """predict: unchanged (counted); initial: x = z; update: x+ = (x + z) / 2, nu = z - x, S = 1."""

    def __init__(self, threshold: float = math.inf, stretch: bool = False) -> None:
        self.nis_threshold = threshold
        self.means: dict[int, np.ndarray] = {}
        self.updated: dict[int, np.ndarray] = {}
        self.innovations: dict[int, np.ndarray] = {}
        if stretch:
            self.predict_steps = self._predict_steps
            self.record_stretch = self._record_stretch

    def predict(self, state: Scalar, t: int, dt: float) -> Scalar:
        return Scalar(state.x.copy(), state.predictions + 1)

    def initial(self, state: Scalar, z: np.ndarray, t: int) -> Scalar:
        return Scalar(z.copy(), state.predictions)

    def propose(self, state: Scalar, z: np.ndarray, rows: np.ndarray, t: int) -> Proposal:
        return Proposal(Scalar((state.x + z) / 2, state.predictions), z - state.x, np.ones((len(z), 1, 1)))

    def commit(self, state: Scalar, z: np.ndarray, rows: np.ndarray, proposal: Proposal, t: int) -> tuple[Any, np.ndarray]:
        return proposal.state, rows

    def record(self, t: int, prior: Scalar, state: Scalar, innovation: Any, used: Any, initialised: np.ndarray) -> None:
        self.means[t] = state.x[:, 0].copy()
        self.updated[t] = np.zeros(len(state.x), dtype=bool) if used is None else used.copy()
        self.innovations[t] = np.zeros(len(state.x)) if innovation is None else innovation[0][:, 0].copy()

    def _predict_steps(self, state: Scalar, t: int, count: int, dt: float) -> tuple[list[Scalar], Scalar]:
        block = []
        for _ in range(count):
            block.append(state)
            state = self.predict(state, t, dt)
        return block[1:], state

    def _record_stretch(self, t: int, stop: int, block: list[Scalar], state: Scalar, predicted: bool, initialised: Any) -> None:
        for offset, value in enumerate(block):
            self.means[t + offset] = value.x[:, 0].copy()
            self.updated[t + offset] = np.zeros(len(value.x), dtype=bool)
        if not predicted:
            self.means[stop - 1] = state.x[:, 0].copy()
            self.updated[stop - 1] = np.zeros(len(state.x), dtype=bool)


def _run(steps: Averaging, z: np.ndarray, usable: np.ndarray) -> Carry:
    batch = z.shape[0]
    start = Carry(Scalar(np.zeros((batch, 1)), np.zeros(batch)), np.zeros(batch, dtype=bool),
                  np.zeros(batch, dtype=np.int64) if steps.nis_threshold != math.inf else None)
    return scan(steps, start, z, usable, 0.1)


def _series(steps: Averaging, what: str) -> np.ndarray:
    values = getattr(steps, what)
    return np.stack([values[t] for t in sorted(values)], 1)


def test_initialise_at_the_first_usable_measurement_then_update() -> None:
    z = np.array([[[4.0], [8.0], [0.0], [2.0]], [[0.0], [0.0], [6.0], [2.0]]])
    usable = np.array([[True, True, False, True], [False, False, True, True]])
    steps = Averaging()
    final = _run(steps, z, usable)
    np.testing.assert_array_equal(_series(steps, "means"), [[4.0, 6.0, 6.0, 4.0], [0.0, 0.0, 6.0, 4.0]])
    np.testing.assert_array_equal(_series(steps, "updated"), [[False, True, False, True], [False, False, False, True]])
    np.testing.assert_array_equal(final.initialised, [True, True])
    np.testing.assert_array_equal(final.state.predictions, [3, 3])  # no prediction at t = 0
    assert first_usable(usable).tolist() == [[True, False, False, False], [False, False, True, False]]


def test_the_gate_keeps_the_prediction_and_a_lost_track_restarts_from_the_third_rejection() -> None:
    values = [0.0, 0.5, 10.0, 11.0, 12.0, 12.5]  # three outliers in a row: a lost track
    z = np.array([[[v] for v in values]])
    steps = Averaging(threshold=4.0)  # |nu| <= 2 passes
    final = _run(steps, z, np.ones((1, len(values)), dtype=bool))
    assert GATE_REINITIALISE_AFTER == 3
    np.testing.assert_array_equal(_series(steps, "means")[0], [0.0, 0.25, 0.25, 0.25, 12.0, 12.25])
    np.testing.assert_array_equal(_series(steps, "updated")[0], [False, True, False, False, False, True])
    np.testing.assert_array_equal(_series(steps, "innovations")[0], [0.0, 0.5, 0.0, 0.0, 0.0, 0.5])
    assert final.rejections.tolist() == [0]


def test_a_stretch_predicted_in_one_call_gives_the_same_steps() -> None:
    rng = np.random.default_rng(0)
    z = rng.normal(size=(3, 40, 1))
    usable = np.zeros((3, 40), dtype=bool)
    usable[:, ::7] = True
    usable[1, :10] = False
    plain, stretched = Averaging(), Averaging(stretch=True)
    a, b = _run(plain, z, usable), _run(stretched, z, usable)
    np.testing.assert_array_equal(_series(plain, "means"), _series(stretched, "means"))
    np.testing.assert_array_equal(_series(plain, "updated"), _series(stretched, "updated"))
    np.testing.assert_array_equal(a.state.predictions, b.state.predictions)


@pytest.mark.parametrize("threshold", [math.inf, 1.0])
def test_one_advance_at_batch_one_is_a_row_of_the_scan(threshold: float) -> None:
    rng = np.random.default_rng(1)
    z = rng.normal(scale=2.0, size=(2, 30, 1))
    usable = rng.random((2, 30)) < 0.6
    batch = Averaging(threshold)
    _run(batch, z, usable)
    for row in range(2):
        online = Averaging(threshold)
        carry = Carry(Scalar(np.zeros((1, 1)), np.zeros(1)), np.zeros(1, dtype=bool),
                      np.zeros(1, dtype=np.int64) if threshold != math.inf else None)
        for t in range(30):
            ok = usable[row, t:t + 1]
            carry, _ = advance(online, carry, z[row, t:t + 1], ok, ok & ~carry.initialised, t, 0.1, predict=t > 0)
        np.testing.assert_array_equal(_series(online, "means")[0], _series(batch, "means")[row])


def test_select_keeps_the_rows_of_any_state_structure() -> None:
    a = Scalar(np.ones((2, 1)), np.ones(2))
    b = Scalar(np.zeros((2, 1)), np.zeros(2))
    out = select(np.array([True, False]), a, b)
    assert out.x[:, 0].tolist() == [1.0, 0.0] and out.predictions.tolist() == [1.0, 0.0]
    assert select(np.array([False, True]), {"R": np.ones((2, 3, 3))}, {"R": np.zeros((2, 3, 3))})["R"][:, 0, 0].tolist() == [0.0, 1.0]
