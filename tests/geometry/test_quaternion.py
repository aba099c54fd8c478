"""Quaternion helpers (Hamilton, wxyz) against known values and scipy (which is xyzw), on numpy
arrays and torch tensors."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch
from scipy import stats
from scipy.spatial.transform import Rotation, Slerp

from fkn_bench.geometry import quaternion as quat


def _random_unit(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.standard_normal((n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _scipy(q: np.ndarray) -> Rotation:
    return Rotation.from_quat(quat.wxyz_to_xyzw(q))


def _same_attitude(a: np.ndarray, b: np.ndarray, atol: float) -> None:
    """``a`` and ``b`` equal up to the sign of each quaternion."""
    sign = np.where(np.sum(a * b, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    np.testing.assert_allclose(a, sign * b, rtol=0, atol=atol)


# ---------------------------------------------------------------------------- product
def test_multiply_known_values() -> None:
    i, j, k = np.eye(4)[1], np.eye(4)[2], np.eye(4)[3]
    # exact in this file: multiply/conjugate/reorder/canonical use only + - * and copies (small
    # integers and 0/1 are exact), the sign tests rely on sign-symmetric rounding, normalize([0, 3, 0,
    # 4]) and slerp(t = 0) are correctly rounded (3/5, sin(0) = 0, cos(0) = 1), random_uniform is seeded
    np.testing.assert_array_equal(quat.multiply(i, j), k)
    np.testing.assert_array_equal(quat.multiply(j, k), i)
    np.testing.assert_array_equal(quat.multiply(k, i), j)
    np.testing.assert_array_equal(quat.multiply(j, i), -k)
    np.testing.assert_array_equal(quat.multiply(i, i), -quat.IDENTITY)
    np.testing.assert_array_equal(quat.multiply([1.0, 2.0, 3.0, 4.0], [5.0, 6.0, 7.0, 8.0]), [-60.0, 12.0, 30.0, 24.0])


def test_multiply_identity_inverse_associativity() -> None:
    rng = np.random.default_rng(0)
    p, q, r = (_random_unit(rng, 500) for _ in range(3))
    np.testing.assert_array_equal(quat.multiply(quat.IDENTITY, q), q)
    np.testing.assert_array_equal(quat.multiply(q, quat.IDENTITY), q)
    inverse = np.broadcast_to(quat.IDENTITY, q.shape)
    np.testing.assert_allclose(quat.multiply(q, quat.conjugate(q)), inverse, atol=1e-15)
    np.testing.assert_allclose(quat.multiply(quat.conjugate(q), q), inverse, atol=1e-15)
    np.testing.assert_allclose(
        quat.multiply(quat.multiply(p, q), r), quat.multiply(p, quat.multiply(q, r)), atol=1e-15
    )
    # non-commutative
    assert np.abs(quat.multiply(p, q) - quat.multiply(q, p)).max() > 0.1


def test_multiply_matches_scipy_composition() -> None:
    """Hamilton ``p (x) q`` is the rotation ``q`` followed by ``p``."""
    rng = np.random.default_rng(1)
    p, q = _random_unit(rng, 200), _random_unit(rng, 200)
    expected = quat.xyzw_to_wxyz((_scipy(p) * _scipy(q)).as_quat())
    _same_attitude(quat.multiply(p, q), expected, atol=1e-14)


def test_multiply_broadcast_out_and_axis() -> None:
    rng = np.random.default_rng(2)
    p, q = _random_unit(rng, 6).reshape(2, 3, 4), _random_unit(rng, 3)
    full = quat.multiply(p, q)
    assert full.shape == (2, 3, 4)
    np.testing.assert_array_equal(full[1, 2], quat.multiply(p[1, 2], q[2]))
    out = np.empty((2, 3, 4))
    assert quat.multiply(p, q, out=out) is out
    np.testing.assert_array_equal(out, full)
    # component-major layout: components on axis 1
    p_cm, q_cm = np.moveaxis(p, -1, 1), np.moveaxis(np.broadcast_to(q, p.shape), -1, 1)
    np.testing.assert_array_equal(quat.multiply(p_cm, q_cm, axis=1), np.moveaxis(full, -1, 1))
    p_before = p.copy()
    quat.multiply(p, q)
    np.testing.assert_array_equal(p, p_before)


def test_conjugate_normalize() -> None:
    np.testing.assert_array_equal(quat.conjugate([1.0, 2.0, -3.0, 4.0]), [1.0, -2.0, 3.0, -4.0])
    np.testing.assert_array_equal(quat.normalize([0.0, 3.0, 0.0, 4.0]), [0.0, 0.6, 0.0, 0.8])
    batch = quat.normalize(np.array([[2.0, 0, 0, 0], [0, 0, 0, -5.0]]))
    np.testing.assert_array_equal(batch, [[1.0, 0, 0, 0], [0, 0, 0, -1.0]])


@pytest.mark.parametrize(
    "bad",
    [[0.0, 0.0, 0.0, 0.0], [[1.0, 0, 0, 0], [0.0, 0, 0, 0]], [np.nan, 1.0, 0, 0], [np.inf, 0, 0, 0]],
)
def test_normalize_raises_on_zero_or_non_finite(bad: list) -> None:
    with pytest.raises(ValueError, match="zero or non-finite"):
        quat.normalize(np.array(bad))


# ---------------------------------------------------------------------------- rotation vectors
def test_rotation_vector_known_values() -> None:
    q = quat.from_rotation_vector([0.0, 0.0, np.pi / 2])
    np.testing.assert_allclose(q, [np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)], atol=1e-16)
    np.testing.assert_array_equal(quat.from_rotation_vector([0.0, 0.0, 0.0]), quat.IDENTITY)
    np.testing.assert_array_equal(quat.to_rotation_vector(quat.IDENTITY), [0.0, 0.0, 0.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a half-turn (w = 0) must not divide by zero
        np.testing.assert_allclose(quat.to_rotation_vector([0.0, 1.0, 0.0, 0.0]), [np.pi, 0.0, 0.0], atol=1e-15)
        np.testing.assert_allclose(
            quat.to_rotation_vector([[0.0, 0.0, 0.6, 0.8], [1.0, 0.0, 0.0, 0.0]]),
            [[0.0, 0.6 * np.pi, 0.8 * np.pi], [0.0, 0.0, 0.0]],
            atol=1e-15,
        )


def test_rotation_vector_round_trip_and_scipy() -> None:
    rng = np.random.default_rng(3)
    axes = rng.standard_normal((1000, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    v = axes * rng.uniform(0.0, np.pi * 0.999, (1000, 1))
    q = quat.from_rotation_vector(v)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)
    np.testing.assert_allclose(quat.to_rotation_vector(q), v, atol=1e-13)
    _same_attitude(q, quat.xyzw_to_wxyz(Rotation.from_rotvec(v).as_quat()), atol=1e-15)
    np.testing.assert_allclose(quat.to_rotation_vector(q), _scipy(q).as_rotvec(), atol=1e-13)


@pytest.mark.parametrize("angle", [1e-300, 1e-15, 1e-12, 1e-9, 1e-8, 1e-5, 1e-3])
def test_rotation_vector_tiny_angles(angle: float) -> None:
    v = angle * np.array([0.48, -0.6, 0.64])
    q = quat.from_rotation_vector(v)
    assert np.all(np.isfinite(q))
    np.testing.assert_allclose(q[1:], np.sin(angle / 2) / angle * v, rtol=1e-15)
    np.testing.assert_allclose(quat.to_rotation_vector(q), v, rtol=1e-12)
    # not exactly unit: only the direction counts
    np.testing.assert_allclose(quat.to_rotation_vector(3.0 * q), v, rtol=1e-12)


@pytest.mark.parametrize("gap", [1e-3, 1e-6, 1e-9, 0.0])
def test_rotation_vector_near_pi(gap: float) -> None:
    axis = np.array([0.48, -0.6, 0.64])
    v = (np.pi - gap) * axis
    q = quat.from_rotation_vector(v)
    np.testing.assert_allclose(quat.to_rotation_vector(q), v, atol=1e-14)
    np.testing.assert_allclose(quat.to_rotation_vector(-q), v, atol=1e-14)


def test_rotation_vector_beyond_pi_gives_shortest_rotation() -> None:
    axis = np.array([0.0, 0.6, 0.8])
    v = 1.5 * np.pi * axis
    np.testing.assert_allclose(quat.to_rotation_vector(quat.from_rotation_vector(v)), -0.5 * np.pi * axis, atol=1e-15)


def test_sign_safety() -> None:
    rng = np.random.default_rng(4)
    q = _random_unit(rng, 1000)
    np.testing.assert_array_equal(quat.to_rotation_vector(q), quat.to_rotation_vector(-q))
    assert np.all(np.linalg.norm(quat.to_rotation_vector(q), axis=1) <= np.pi)
    # zero up to rounding of the product (an arccos of the dot product would give ~1e-8)
    np.testing.assert_allclose(quat.angle_between(q, -q), 0.0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(quat.angle_between(q, q), 0.0, rtol=0, atol=1e-15)
    p = _random_unit(rng, 1000)
    a = quat.angle_between(p, q)
    np.testing.assert_array_equal(quat.angle_between(p, -q), a)
    np.testing.assert_array_equal(quat.angle_between(-p, q), a)
    np.testing.assert_allclose(a, (_scipy(p).inv() * _scipy(q)).magnitude(), atol=1e-12)
    np.testing.assert_array_equal(quat.canonical(-q)[:, 0] >= 0, True)
    np.testing.assert_array_equal(quat.canonical(q), quat.canonical(-q))
    aligned = quat.align_sign(-q, q)
    np.testing.assert_array_equal(aligned, q)


def test_angle_between_tiny_angle() -> None:
    q = quat.normalize(np.array([0.3, -0.5, 0.1, 0.8]))
    for angle in (1e-10, 1e-8, 1e-6):
        p = quat.multiply(quat.from_rotation_vector([0.0, angle, 0.0]), q)
        np.testing.assert_allclose(quat.angle_between(q, p), angle, rtol=1e-5)


def test_error_rotation_vector() -> None:
    rng = np.random.default_rng(5)
    q_est = _random_unit(rng, 500)
    d = 0.3 * rng.standard_normal((500, 3))
    q_true = quat.multiply(quat.from_rotation_vector(d), q_est)
    np.testing.assert_allclose(quat.error_rotation_vector(q_true, q_est), d, atol=1e-14)
    np.testing.assert_allclose(quat.error_rotation_vector(-q_true, q_est), d, atol=1e-14)
    np.testing.assert_allclose(quat.error_rotation_vector(q_true, -q_est), d, atol=1e-14)


# ---------------------------------------------------------------------------- matrices
def test_rotation_matrix_and_rotate_match_scipy() -> None:
    rng = np.random.default_rng(6)
    q = _random_unit(rng, 300)
    v = rng.standard_normal((300, 3))
    np.testing.assert_allclose(quat.rotation_matrix(q), _scipy(q).as_matrix(), atol=1e-15)
    np.testing.assert_allclose(quat.rotate(q, v, transpose=True), _scipy(q).inv().apply(v), atol=1e-14)
    np.testing.assert_allclose(quat.rotate(q, v), _scipy(q).apply(v), atol=1e-14)
    # rotate equals q (x) [0, v] (x) q*
    pure = np.concatenate([np.zeros((300, 1)), v], axis=1)
    sandwich = quat.multiply(quat.multiply(q, pure), quat.conjugate(q))
    np.testing.assert_allclose(quat.rotate(q, v), sandwich[:, 1:], atol=1e-14)
    # known value: 90 degrees about z maps x to y
    rz = quat.from_rotation_vector([0.0, 0.0, np.pi / 2])
    np.testing.assert_allclose(quat.rotate(rz, [1.0, 0.0, 0.0]), [0.0, 1.0, 0.0], atol=1e-15)


def test_theta_matrix() -> None:
    rng = np.random.default_rng(7)
    q = _random_unit(rng, 300)
    w = rng.standard_normal((300, 3))
    theta = quat.theta_matrix(q)
    assert theta.shape == (300, 4, 3)
    pure = np.concatenate([np.zeros((300, 1)), w], axis=1)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", theta, w), quat.multiply(pure, q), atol=1e-15)
    # the paper's matrix, written out (FlexKalmanNet eq. 11)
    qw, qx, qy, qz = 0.1, 0.2, 0.3, 0.4
    expected = [[-qx, -qy, -qz], [qw, qz, -qy], [-qz, qw, qx], [qy, -qx, qw]]
    np.testing.assert_array_equal(quat.theta_matrix([qw, qx, qy, qz]), expected)
    # orthonormal columns, orthogonal to q
    gram = np.einsum("nij,nik->njk", theta, theta)
    np.testing.assert_allclose(gram, np.broadcast_to(np.eye(3), (300, 3, 3)), atol=1e-15)
    np.testing.assert_allclose(np.einsum("nij,ni->nj", theta, q), 0.0, atol=1e-15)


# ---------------------------------------------------------------------------- slerp
def test_slerp_endpoints_and_midpoint() -> None:
    rng = np.random.default_rng(8)
    q0, q1 = _random_unit(rng, 200), _random_unit(rng, 200)
    np.testing.assert_array_equal(quat.slerp(q0, q1, 0.0), q0)
    _same_attitude(quat.slerp(q0, q1, 1.0), q1, atol=1e-14)
    mid = quat.slerp(q0, q1, 0.5)
    total = quat.angle_between(q0, q1)
    np.testing.assert_allclose(quat.angle_between(q0, mid), total / 2, atol=1e-13)
    np.testing.assert_allclose(quat.angle_between(mid, q1), total / 2, atol=1e-13)
    # shortest arc: the sign of q1 does not matter
    np.testing.assert_allclose(quat.slerp(q0, -q1, 0.5), mid, atol=1e-15)
    for i in range(0, 200, 20):
        reference = Slerp([0.0, 1.0], Rotation.concatenate([_scipy(q0[i]), _scipy(q1[i])]))([0.3])
        _same_attitude(quat.slerp(q0[i], q1[i], 0.3), quat.xyzw_to_wxyz(reference.as_quat()[0]), atol=1e-13)


def test_slerp_known_value_and_broadcast() -> None:
    q1 = quat.from_rotation_vector([0.0, 0.0, 1.0])
    fractions = np.array([0.0, 0.25, 0.5, 1.0])
    out = quat.slerp(quat.IDENTITY, q1, fractions)
    assert out.shape == (4, 4)
    np.testing.assert_allclose(quat.to_rotation_vector(out), np.outer(fractions, [0.0, 0.0, 1.0]), atol=1e-15)


# ---------------------------------------------------------------------------- sampling and layout
def test_random_uniform_is_uniform() -> None:
    rng = np.random.default_rng(9)
    n = 200_000
    q = quat.random_uniform(rng, n)
    assert q.shape == (n, 4)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)
    assert np.all(q[:, 0] >= 0)  # canonical sign
    # uniform on S^3: every component has E[c^2] = 1/4; the vector part has mean 0
    np.testing.assert_allclose(np.mean(q**2, axis=0), 0.25, atol=0.004)
    np.testing.assert_allclose(np.mean(q[:, 1:], axis=0), 0.0, atol=0.005)
    # |w| has density (4/pi) sqrt(1 - w^2) on [0, 1]: mean 4 / (3 pi)
    assert abs(np.mean(q[:, 0]) - 4 / (3 * np.pi)) < 0.003
    cdf = lambda w: (2 / np.pi) * (w * np.sqrt(1 - w**2) + np.arcsin(w))  # noqa: E731
    assert stats.kstest(q[:5000, 0], cdf).pvalue > 0.001
    # a rotated fixed vector is uniform on the sphere
    v = quat.rotate(q[:20000], [0.0, 0.0, 1.0])
    np.testing.assert_allclose(np.mean(v, axis=0), 0.0, atol=0.02)
    np.testing.assert_allclose(np.mean(v**2, axis=0), 1 / 3, atol=0.01)


def test_random_uniform_shapes_and_determinism() -> None:
    assert quat.random_uniform(np.random.default_rng(0)).shape == (4,)
    assert quat.random_uniform(np.random.default_rng(0), (2, 3)).shape == (2, 3, 4)
    a = quat.random_uniform(np.random.default_rng(11), 5)
    b = quat.random_uniform(np.random.default_rng(11), 5)
    np.testing.assert_array_equal(a, b)


def test_xyzw_wxyz_conversion() -> None:
    np.testing.assert_array_equal(quat.wxyz_to_xyzw([1.0, 2.0, 3.0, 4.0]), [2.0, 3.0, 4.0, 1.0])
    np.testing.assert_array_equal(quat.xyzw_to_wxyz([2.0, 3.0, 4.0, 1.0]), [1.0, 2.0, 3.0, 4.0])
    rng = np.random.default_rng(10)
    q = _random_unit(rng, 50).reshape(5, 10, 4)
    np.testing.assert_array_equal(quat.xyzw_to_wxyz(quat.wxyz_to_xyzw(q)), q)
    np.testing.assert_array_equal(quat.wxyz_to_xyzw(q)[..., 3], q[..., 0])


def test_left_and_right_matrices() -> None:
    """``Theta(q) w = Omega(w) q = [0, w] (x) q``, ``Theta_R(q) w = Omega_R(w) q = q (x) [0, w]``,
    ``[v x] u = v x u``."""
    rng = np.random.default_rng(12)
    q, w, u = _random_unit(rng, 50), rng.standard_normal((50, 3)), rng.standard_normal((50, 3))
    pure = np.concatenate([np.zeros((50, 1)), w], axis=1)
    apply = lambda M, x: np.einsum("nij,nj->ni", M, x)  # noqa: E731
    np.testing.assert_allclose(apply(quat.omega_matrix(w), q), quat.multiply(pure, q), atol=1e-15)
    np.testing.assert_allclose(apply(quat.right_theta_matrix(q), w), quat.multiply(q, pure), atol=1e-15)
    np.testing.assert_allclose(apply(quat.right_omega_matrix(w), q), quat.multiply(q, pure), atol=1e-15)
    np.testing.assert_allclose(apply(quat.skew(w), u), np.cross(w, u), atol=1e-15)
    assert quat.omega_matrix(w).shape == (50, 4, 4) and quat.right_theta_matrix(q).shape == (50, 4, 3)


# ---------------------------------------------------------------------------- numpy evaluation
def _rows() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random and edge-case rows: quaternions (unit, scaled, w < 0, half-turns, zero, NaN), a second
    set, rotation vectors (zero, tiny, near pi, huge, non-finite)."""
    rng = np.random.default_rng(13)
    n = 240
    scale = np.array([1.0, 1e-12, 1e-9, 1e-6, 0.5, 3.0, 1e8])[rng.integers(0, 7, (n, 1))]
    q, p, v = rng.standard_normal((n, 4)) * scale, rng.standard_normal((n, 4)), rng.standard_normal((n, 3)) * scale
    q[:4] = 0.0
    q[4:8, 0] = 0.0
    q[8:12, 1:] *= 1e-10
    q[12:16, 0] = -np.abs(q[12:16, 0])
    q[16:18, 2] = np.nan
    q[18:20] = [[1e-10, 1e-12, 0.0, 0.0]]
    v[:4] = 0.0
    v[4:6, 0] = np.nan
    v[6:8, 1] = np.inf
    v[8:12] = (np.pi - 1e-9) * np.array([0.48, -0.6, 0.64])
    return q, p, v


def test_single_rows_give_the_bits_of_a_batch() -> None:
    """A row alone (``(1, 4)``/``(4,)``: evaluated on Python floats) gives exactly the bits it
    gets inside a batch: an episode is the same whatever the batch it is generated in."""
    q, p, v = _rows()
    with np.errstate(all="ignore"):
        batch = {
            "multiply": quat.multiply(q, p),
            "from_rotation_vector": quat.from_rotation_vector(v),
            "to_rotation_vector": quat.to_rotation_vector(q),
            "rotation_matrix": quat.rotation_matrix(q),
            "align_sign": quat.align_sign(q, p),
        }
        for i in range(len(q)):
            row = {
                "multiply": quat.multiply(q[i : i + 1], p[i : i + 1]),
                "from_rotation_vector": quat.from_rotation_vector(v[i : i + 1]),
                "to_rotation_vector": quat.to_rotation_vector(q[i : i + 1]),
                "rotation_matrix": quat.rotation_matrix(q[i : i + 1]),
                "align_sign": quat.align_sign(q[i : i + 1], p[i : i + 1]),
            }
            for name, value in row.items():
                assert value.tobytes() == batch[name][i : i + 1].tobytes(), (name, i)
            assert quat.multiply(q[i], p[i]).tobytes() == batch["multiply"][i].tobytes()


def test_numpy_inputs_are_float64_and_lists() -> None:
    assert quat.conjugate(np.array([1, 2, 3, 4], dtype=np.float32)).dtype == np.float64
    assert quat.theta_matrix([1, 0, 0, 0]).dtype == np.float64
    np.testing.assert_array_equal(quat.rotate([1.0, 0.0, 0.0, 0.0], [1, 2, 3]), [1.0, 2.0, 3.0])


# ---------------------------------------------------------------------------- torch
def test_torch_matches_numpy() -> None:
    """Every function takes torch tensors and returns tensors of the numpy result (to rounding:
    torch evaluates the linear maps as products with constant matrices)."""
    rng = np.random.default_rng(14)
    q, p, v = _random_unit(rng, 30).reshape(5, 6, 4), _random_unit(rng, 30).reshape(5, 6, 4), rng.standard_normal((5, 6, 3))
    v[0, 0] = 0.0
    v[0, 1] = 1e-8
    calls = {
        "multiply": lambda m, a, b, x: m.multiply(a, b),
        "conjugate": lambda m, a, b, x: m.conjugate(a),
        "normalize": lambda m, a, b, x: m.normalize(2.0 * a),
        "canonical": lambda m, a, b, x: m.canonical(a),
        "align_sign": lambda m, a, b, x: m.align_sign(a, b),
        "from_rotation_vector": lambda m, a, b, x: m.from_rotation_vector(x),
        "to_rotation_vector": lambda m, a, b, x: m.to_rotation_vector(a),
        "error_rotation_vector": lambda m, a, b, x: m.error_rotation_vector(a, b),
        "angle_between": lambda m, a, b, x: m.angle_between(a, b),
        "rotation_matrix": lambda m, a, b, x: m.rotation_matrix(a),
        "rotate": lambda m, a, b, x: m.rotate(a, x),
        "rotate-transpose": lambda m, a, b, x: m.rotate(a, x, transpose=True),
        "rotation_jacobian": lambda m, a, b, x: m.rotation_jacobian(a, x),
        "theta_matrix": lambda m, a, b, x: m.theta_matrix(a),
        "omega_matrix": lambda m, a, b, x: m.omega_matrix(x),
        "right_theta_matrix": lambda m, a, b, x: m.right_theta_matrix(a),
        "right_omega_matrix": lambda m, a, b, x: m.right_omega_matrix(x),
        "skew": lambda m, a, b, x: m.skew(x),
        "slerp": lambda m, a, b, x: m.slerp(a, b, 0.3),
        "wxyz_to_xyzw": lambda m, a, b, x: m.wxyz_to_xyzw(a),
        "xyzw_to_wxyz": lambda m, a, b, x: m.xyzw_to_wxyz(a),
    }
    tq, tp, tv = (torch.from_numpy(a) for a in (q, p, v))
    for name, call in calls.items():
        expected, got = call(quat, q, p, v), call(quat, tq, tp, tv)
        assert isinstance(got, torch.Tensor) and got.dtype == torch.float64, name
        np.testing.assert_allclose(got.numpy(), expected, rtol=0, atol=1e-14, err_msg=name)
    with pytest.raises(ValueError, match="zero or non-finite"):
        quat.normalize(torch.zeros(4, dtype=torch.float64))
    with pytest.raises(ValueError, match="numpy"):
        quat.multiply(tq, tp, axis=0)


def test_torch_gradients() -> None:
    """Exact first derivatives (``gradcheck``), finite at zero rotation and at a zero quaternion (a
    masked row); ``rotation_jacobian`` is the derivative of ``rotate``, also for a non-unit ``q``."""
    rng = np.random.default_rng(15)
    q = torch.tensor(_random_unit(rng, 3) * [[1.0], [1.5], [0.7]], requires_grad=True)
    v = torch.tensor(rng.standard_normal((3, 3)), requires_grad=True)
    for f in (quat.multiply, lambda a, b: quat.error_rotation_vector(a, b[:, [0, 1, 2, 0]])):
        assert torch.autograd.gradcheck(f, (q, q.detach().flip(0).requires_grad_()))
    for f in (quat.from_rotation_vector, quat.skew, quat.omega_matrix):
        assert torch.autograd.gradcheck(f, (v,))
    for f in (quat.to_rotation_vector, quat.rotation_matrix, quat.theta_matrix):
        assert torch.autograd.gradcheck(f, (q,))
    for transpose in (False, True):
        for i in range(3):
            jacobian = torch.autograd.functional.jacobian(lambda a: quat.rotate(a, v[i], transpose=transpose), q[i])
            torch.testing.assert_close(quat.rotation_jacobian(q[i], v[i], transpose=transpose), jacobian, rtol=0, atol=1e-14)
    # zero rotation, and a zero quaternion: finite gradients through the series branches
    zero = torch.zeros((1, 3), dtype=torch.float64, requires_grad=True)
    quat.from_rotation_vector(zero).sum().backward()
    np.testing.assert_array_equal(zero.grad.numpy(), [[0.5, 0.5, 0.5]])
    for q0 in ([[1.0, 0.0, 0.0, 0.0]], [[0.0, 0.0, 0.0, 0.0]]):
        t = torch.tensor(q0, dtype=torch.float64, requires_grad=True)
        quat.to_rotation_vector(t).sum().backward()
        assert torch.isfinite(t.grad).all()
