"""Rigid alignment (fkn_bench.geometry.alignment): Umeyama's closed form recovers a known transform."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.geometry import quaternion as quat
from fkn_bench.geometry.alignment import attitude_alignment, matrix_to_quaternion, umeyama

RNG = np.random.default_rng(7)
Q = quat.normalize(np.array([0.3, -0.5, 0.7, 0.4]))
R = quat.rotation_matrix(Q)
T = np.array([1.5, -2.0, 0.25])


def test_umeyama_recovers_a_known_rotation_and_translation() -> None:
    source = RNG.normal(size=(50, 3))
    transform = umeyama(source, source @ R.T + T)
    np.testing.assert_allclose(transform.rotation, R, atol=1e-12)
    np.testing.assert_allclose(transform.translation, T, atol=1e-12)
    assert transform.rms_residual < 1e-12 and transform.points == 50 and transform.method == "positions"
    assert abs(transform.angle - np.linalg.norm(quat.to_rotation_vector(Q))) < 1e-12
    np.testing.assert_allclose(transform.apply(source), source @ R.T + T, atol=1e-12)


def test_umeyama_is_the_least_squares_fit_and_never_a_reflection() -> None:
    source = RNG.normal(size=(40, 3))
    noisy = source @ R.T + T + 0.01 * RNG.normal(size=source.shape)
    transform = umeyama(source, noisy)
    assert np.linalg.det(transform.rotation) == pytest.approx(1.0)
    assert np.degrees(np.arccos((np.trace(transform.rotation.T @ R) - 1) / 2)) < 1.0
    mirrored = umeyama(source, source * np.array([1.0, 1.0, -1.0]))  # the best proper rotation of a mirror image
    assert np.linalg.det(mirrored.rotation) == pytest.approx(1.0)


def test_collinear_or_too_few_points_are_refused() -> None:
    line = np.outer(np.arange(10.0), [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="collinear"):
        umeyama(line, line + 1.0)
    with pytest.raises(ValueError, match="at least 3"):
        umeyama(line[:2], line[:2])


def test_attitude_alignment_takes_the_rotation_from_attitudes_where_positions_are_on_a_line() -> None:
    line = np.outer(np.arange(10.0), [1.0, 2.0, 3.0])
    attitudes = quat.rotation_matrix(quat.random_uniform(RNG, 10))
    transform = attitude_alignment(line, line @ R.T + T, attitudes, R @ attitudes)
    np.testing.assert_allclose(transform.rotation, R, atol=1e-12)
    np.testing.assert_allclose(transform.translation, T, atol=1e-12)
    assert transform.method == "attitudes"


def test_matrix_to_quaternion_inverts_rotation_matrix_on_every_branch() -> None:
    for q in [Q, np.array([0.0, 1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0, 0.0]), np.array([0.1, 0.0, 0.0, 0.99]),
              *quat.random_uniform(RNG, 20)]:
        q = quat.normalize(q)
        got = matrix_to_quaternion(quat.rotation_matrix(q))
        np.testing.assert_allclose(got, q if q[0] >= 0 else -q, atol=1e-12)
