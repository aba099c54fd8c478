"""External estimates on the truth's grid (fkn_bench.envs.association): interpolation within the
tolerance, the prior before the first estimate, the latest estimate held across gaps."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.envs.association import ExternalSeries, associate
from fkn_bench.geometry import quaternion as quat
from fkn_bench.recordings import RecordingError

S = 10**9


def _series(stamps_s: list[float]) -> ExternalSeries:
    stamps = np.round(np.array(stamps_s) * S).astype(np.int64)
    angles = np.array(stamps_s)  # a turn of 1 rad/s about z, moving 1 m/s along x
    poses = np.concatenate([quat.from_rotation_vector(np.outer(angles, [0, 0, 1.0])), np.outer(angles, [1.0, 0, 0])], 1)
    twists = np.tile([0, 0, 1.0, 1.0, 0, 0], (len(stamps), 1))
    return ExternalSeries("external:x", "test", stamps, poses, stamps, twists, "given")


def test_interpolation_prior_and_hold() -> None:
    series = _series([1.0, 1.2, 1.4, 2.4, 2.6])  # median interval 0.2 s: tolerance 0.4 s; a 1 s gap
    grid = np.round(np.arange(0, 31) * 0.1 * S).astype(np.int64)  # 0 .. 3 s
    out = associate(series, grid)
    assert out.tolerance_s == pytest.approx(0.4)
    t = grid / S
    expected_associated = ((t >= 1.0 - 1e-9) & (t <= 1.4 + 1e-9)) | ((t >= 2.4 - 1e-9) & (t <= 2.6 + 1e-9))
    np.testing.assert_array_equal(out.associated, expected_associated)
    np.testing.assert_array_equal(out.initialised, t >= 1.0 - 1e-9)
    assert out.counts == {"associated": 8, "held": 13, "before_first_estimate": 10}
    np.testing.assert_array_equal(out.states[:10], np.tile([1.0] + [0.0] * 12, (10, 1)))  # the prior
    k = 11  # 1.1 s: slerp / linear between 1.0 and 1.2
    np.testing.assert_allclose(quat.to_rotation_vector(out.states[k, :4]), [0, 0, 1.1], atol=1e-12)
    np.testing.assert_allclose(out.states[k, 4:7], [1.1, 0, 0], atol=1e-12)
    np.testing.assert_array_equal(out.states[20], out.states[14])  # 2.0 s, in the gap: held from 1.4 s
    np.testing.assert_array_equal(out.states[30], out.states[26])  # after the last stamp: held
    wide = associate(series, grid, tolerance_s=0.6)  # of the 1 s gap, 1.8, 1.9 and 2.0 s are within 0.6 s of both ends
    assert wide.counts["associated"] == 8 + 3 and wide.counts["held"] == 10


def test_an_estimate_on_another_clock_is_refused() -> None:
    grid = np.round(np.arange(0, 10) * 0.1 * S).astype(np.int64) + 100 * S
    with pytest.raises(RecordingError, match="same clock"):
        associate(_series([1.0, 1.2, 1.4]), grid)
    with pytest.raises(ValueError, match="positive"):
        associate(_series([1.0, 1.2, 1.4]), grid, tolerance_s=0.0)
