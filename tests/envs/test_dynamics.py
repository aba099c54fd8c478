"""Ground-truth motion: forced rotation against its closed form (via scipy), torque-free
tumbling against conservation laws, and translation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fkn_bench.envs import generate_episodes
from fkn_bench.envs.dynamics import ForcedRotation, FreeTumble
from fkn_bench.envs.measurements import stream
from fkn_bench.geometry import quaternion as quat
from fkn_bench.scenarios import ASTROBEE_INERTIA, get_scenario

def angular_momentum_world(attitude: np.ndarray, omega_world: np.ndarray, inertia: np.ndarray) -> np.ndarray:
    """World-frame angular momentum ``R J R^T omega`` (kg m^2/s) of ``(..., 4)``/``(..., 3)`` inputs."""
    omega_body = quat.rotate(quat.conjugate(attitude), omega_world)
    return quat.rotate(attitude, np.asarray(inertia, dtype=float) * omega_body)


def kinetic_energy(attitude: np.ndarray, omega_world: np.ndarray, inertia: np.ndarray) -> np.ndarray:
    """Rotational kinetic energy ``1/2 w^T J w`` (J) with ``w`` the body rate."""
    omega_body = quat.rotate(quat.conjugate(attitude), omega_world)
    return 0.5 * np.sum(np.asarray(inertia, dtype=float) * omega_body**2, axis=-1)


DS1_RATE = (0.02, 0.04, 0.06)
DS2_RATE = (0.10, 0.20, 0.30)


def _closed_form(q0: np.ndarray, omega: np.ndarray, times: np.ndarray) -> np.ndarray:
    """``exp(omega t / 2) (x) q0`` with scipy (xyzw): a world-frame rotation applied after q0."""
    rotation = Rotation.from_rotvec(times[:, None] * omega[None, :]) * Rotation.from_quat(quat.wxyz_to_xyzw(q0))
    return quat.xyzw_to_wxyz(rotation.as_quat())


def _assert_same_attitudes(a: np.ndarray, b: np.ndarray, atol: float) -> None:
    sign = np.where(np.sum(a * b, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    np.testing.assert_allclose(a, sign * b, rtol=0, atol=atol)


def _numpy_free_tumble(q0: np.ndarray, omega_world: np.ndarray, inertia: np.ndarray, dt: float, substeps: int,
                       n: int) -> tuple[np.ndarray, np.ndarray]:
    """An independent element-wise numpy RK4 of the torque-free rigid body (the implementation
    FreeTumble's compiled kernel replaced): attitudes ``(n, B, 4)`` and world rates ``(n, B, 3)``."""
    J = np.broadcast_to(np.asarray(inertia, dtype=float), (len(q0), 3))
    a = np.stack([(J[:, 1] - J[:, 2]) / J[:, 0], (J[:, 2] - J[:, 0]) / J[:, 1], (J[:, 0] - J[:, 1]) / J[:, 2]], axis=1)

    def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
        w, x, y, z = q.T
        t = 2.0 * np.stack([y * v[:, 2] - z * v[:, 1], z * v[:, 0] - x * v[:, 2], x * v[:, 1] - y * v[:, 0]], axis=1)
        return np.stack([v[:, 0] + w * t[:, 0] + (y * t[:, 2] - z * t[:, 1]),
                         v[:, 1] + w * t[:, 1] + (z * t[:, 0] - x * t[:, 2]),
                         v[:, 2] + w * t[:, 2] + (x * t[:, 1] - y * t[:, 0])], axis=1)

    def derivative(s: np.ndarray) -> np.ndarray:
        w, x, y, z, ox, oy, oz = s.T
        return np.stack([-0.5 * (x * ox + y * oy + z * oz), 0.5 * (w * ox + y * oz - z * oy),
                         0.5 * (w * oy + z * ox - x * oz), 0.5 * (w * oz + x * oy - y * ox),
                         a[:, 0] * oy * oz, a[:, 1] * oz * ox, a[:, 2] * ox * oy], axis=1)

    h = dt / substeps
    state = np.concatenate([q0, rotate(q0 * [1.0, -1.0, -1.0, -1.0], omega_world)], axis=1)
    qs, ws = [], []
    for i in range(n):
        if i:
            for _ in range(substeps):
                k1 = derivative(state)
                k2 = derivative(state + (0.5 * h) * k1)
                k3 = derivative(state + (0.5 * h) * k2)
                k4 = derivative(state + h * k3)
                state = state + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            state[:, :4] /= np.sqrt(np.sum(state[:, :4] * state[:, :4], axis=1))[:, None]
        qs.append(state[:, :4].copy())
        ws.append(rotate(state[:, :4], state[:, 4:]))
    return np.array(qs), np.array(ws)


@pytest.mark.parametrize("substeps", [1, 3])
def test_free_tumble_kernel_is_the_element_wise_rk4_bit_for_bit(substeps: int) -> None:
    """The compiled integration (:func:`fkn_bench.models.rigid_body_kernels.integrate_samples`) performs
    the numpy RK4's IEEE operations in the same order: every sample equal, chunked or not (exact:
    the same element-wise operations on the same values; a fused multiply-add or a reordered sum
    would differ in the last bits within a few steps and grow on a tumble)."""
    rng = np.random.default_rng(3)
    q0 = quat.random_uniform(rng, 3)
    omega = rng.normal(size=(3, 3)) * [[0.05], [0.5], [2.0]]
    inertia = np.array(ASTROBEE_INERTIA) * (1 + 0.2 * rng.uniform(-1, 1, size=(3, 3)))
    q_ref, w_ref = _numpy_free_tumble(q0, omega, inertia, 0.1, substeps, 400)
    tumble = FreeTumble(q0, omega, inertia, 0.1, substeps)
    q1, w1 = tumble.advance(1)
    q2, w2 = tumble.advance(399, step_major=True)
    np.testing.assert_array_equal(np.concatenate([q1.transpose(2, 0, 1), q2.transpose(0, 2, 1)]), q_ref)
    np.testing.assert_array_equal(np.concatenate([w1.transpose(2, 0, 1), w2.transpose(0, 2, 1)]), w_ref)


# ---------------------------------------------------------------------------- forced rotation
# exact comparisons in this file: copies (rates, positions, velocities), cos(0) = 1 and sin(0) = 0 at
# t = 0, and chunked vs whole sampling or integration, which are the same element-wise operations
# (ForcedRotation's closed form, FreeTumble's element-wise RK4) on the same values
def test_forced_rotation_matches_closed_form() -> None:
    rng = np.random.default_rng(0)
    q0 = quat.random_uniform(rng, 4)
    omega = np.array([DS1_RATE, DS2_RATE, [0.0, 0.0, -1.3], [0.0, 0.0, 0.0]])
    dt, n = 0.1, 3000
    q, w = ForcedRotation(q0, omega, dt).sample(0, n)
    assert q.shape == (4, 4, n) and w.shape == (4, 3, n)
    times = np.arange(n) * dt
    for b in range(4):
        _assert_same_attitudes(q[b].T, _closed_form(q0[b], omega[b], times), atol=1e-12)
        np.testing.assert_array_equal(w[b].T, np.broadcast_to(omega[b], (n, 3)))
    np.testing.assert_array_equal(q[:, :, 0], q0)
    np.testing.assert_array_equal(q[3], np.broadcast_to(q0[3][:, None], (4, n)))  # zero rate
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)


def test_forced_rotation_satisfies_the_papers_kinematics() -> None:
    """``q' = 1/2 Theta(q) w``: central differences of the samples match the model."""
    q0 = quat.normalize(np.array([[0.3, -0.5, 0.1, 0.8]]))
    omega = np.array([DS2_RATE])
    dt = 0.1
    q, _ = ForcedRotation(q0, omega, dt).sample(0, 200)
    q = q[0].T
    derivative = (q[2:] - q[:-2]) / (2 * dt)
    model = 0.5 * np.einsum("nij,j->ni", quat.theta_matrix(q[1:-1]), omega[0])
    np.testing.assert_allclose(derivative, model, atol=1e-4)  # O(dt^2 |w|^3)


def test_forced_rotation_chunks_and_seek() -> None:
    rng = np.random.default_rng(1)
    q0 = quat.random_uniform(rng, 2)
    omega = np.array([DS1_RATE, DS2_RATE])
    whole_q, whole_w = ForcedRotation(q0, omega, 0.1).sample(0, 1000)
    rot = ForcedRotation(q0, omega, 0.1)
    parts = [rot.advance(n) for n in (1, 99, 400, 500)]
    np.testing.assert_array_equal(np.concatenate([p[0] for p in parts], axis=2), whole_q)
    np.testing.assert_array_equal(np.concatenate([p[1] for p in parts], axis=2), whole_w)
    rot.seek(250)
    np.testing.assert_array_equal(rot.advance(10)[0], whole_q[:, :, 250:260])


def test_ds1_truth_is_forced_closed_form() -> None:
    episodes = generate_episodes(get_scenario("ds1"), [0, 7])
    times = np.arange(16000) * 0.1
    np.testing.assert_array_equal(episodes.times, times)
    for b in range(2):
        truth = episodes.truth[b]
        _assert_same_attitudes(truth[:, :4], _closed_form(truth[0, :4], np.array(DS1_RATE), times), atol=1e-12)
        np.testing.assert_array_equal(truth[:, 7:10], np.broadcast_to(DS1_RATE, (16000, 3)))
    # the initial attitude is the seed's uniformly random draw
    np.testing.assert_array_equal(episodes.truth[1, 0, :4], quat.random_uniform(stream(7, "attitude0")))


# ---------------------------------------------------------------------------- free tumbling
@pytest.fixture(scope="module")
def full_tumbles() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Full 16000-step torque-free tumbles at dt = 0.1 s with Astrobee's inertia, one batch:
    ds1's and ds2's rates from seed 0's initial attitude, and ds1's rate from the identity.
    Returns ``name -> (q (T, 4), w (T, 3))``."""
    q0 = quat.random_uniform(stream(0, "attitude0"))
    attitudes = np.array([q0, q0, quat.IDENTITY])
    rates = np.array([DS1_RATE, DS2_RATE, DS1_RATE])
    q, w = FreeTumble(attitudes, rates, ASTROBEE_INERTIA, 0.1).advance(16000)
    names = ("ds1-rate", "ds2-rate", "ds1-rate-identity")
    return {name: (q[b].T, w[b].T) for b, name in enumerate(names)}


def test_scenarios_tumble_with_astrobee_inertia(full_tumbles: dict) -> None:
    for name, key in (("tumble-slow", "ds1-rate"), ("tumble-fast", "ds2-rate")):
        truth = generate_episodes(get_scenario(name, n_steps=1000), [0]).truth[0]
        q, w = full_tumbles[key]
        np.testing.assert_array_equal(truth[:, :4], q[:1000])
        np.testing.assert_array_equal(truth[:, 7:10], w[:1000])


@pytest.mark.parametrize(
    ("key", "rate"), [("ds1-rate", DS1_RATE), ("ds2-rate", DS2_RATE), ("ds1-rate-identity", DS1_RATE)]
)
def test_free_tumble_conserves_energy_and_momentum(full_tumbles: dict, key: str, rate: tuple) -> None:
    q, w = full_tumbles[key]
    assert len(q) == 16000
    np.testing.assert_allclose(w[0], rate, rtol=1e-15)
    energy = kinetic_energy(q, w, ASTROBEE_INERTIA)
    momentum = angular_momentum_world(q, w, ASTROBEE_INERTIA)
    assert np.max(np.abs(energy / energy[0] - 1.0)) < 1e-8
    assert np.max(np.linalg.norm(momentum - momentum[0], axis=1)) / np.linalg.norm(momentum[0]) < 1e-8
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)


@pytest.mark.parametrize("key", ["ds1-rate", "ds2-rate", "ds1-rate-identity"])
def test_free_tumble_is_not_constant_rate(full_tumbles: dict, key: str) -> None:
    """Astrobee's inertia is not isotropic: over the 1600 s episode the world-frame rate wobbles
    by several percent (about 14% for ds1's rate), unlike forced rotation."""
    _, w = full_tumbles[key]
    variation = np.linalg.norm(w - w[0], axis=1) / np.linalg.norm(w[0])
    assert variation.max() > 0.05
    assert variation.max() < 0.3  # a wobble, not a blow-up


def test_free_tumble_wobble_from_identity(full_tumbles: dict) -> None:
    q, w = full_tumbles["ds1-rate-identity"]
    variation = np.linalg.norm(w - w[0], axis=1) / np.linalg.norm(w[0])
    assert 0.08 < variation.max() < 0.2
    body = quat.rotate(quat.conjugate(q), w)
    assert np.max(np.linalg.norm(body - body[0], axis=1)) / np.linalg.norm(w[0]) > 1.0  # body rate swings ~120%


@pytest.mark.parametrize(
    ("base", "forced_name", "atol"), [("tumble-slow", "ds1", 5e-11), ("tumble-fast", "ds2", 1.5e-7)]
)
def test_isotropic_free_tumble_equals_forced_rotation(base: str, forced_name: str, atol: float) -> None:
    """With J = I, torque-free motion keeps the world rate and follows the closed form, up to
    RK4's global phase error (~ (|w| dt)^4: 5^4 times larger at ds2's rate than at ds1's)."""
    free = generate_episodes(get_scenario(base, inertia=(1.0, 1.0, 1.0), n_steps=4000), [3])
    forced = generate_episodes(get_scenario(forced_name, n_steps=4000), [3])
    _assert_same_attitudes(free.truth[0, :, :4], forced.truth[0, :, :4], atol=atol)
    np.testing.assert_allclose(free.truth[0, :, 7:10], forced.truth[0, :, 7:10], atol=1e-14)
    np.testing.assert_array_equal(free.truth[0, :, 4:7], forced.truth[0, :, 4:7])


def test_free_tumble_converges_at_fourth_order() -> None:
    q0 = quat.random_uniform(np.random.default_rng(4), 1)
    omega = np.array([DS2_RATE])
    exact, _ = ForcedRotation(q0, omega, 0.1).sample(0, 1000)
    errors = []
    for substeps in (1, 2):
        q, _ = FreeTumble(q0, omega, (1.0, 1.0, 1.0), 0.1, substeps=substeps).advance(1000)
        errors.append(np.abs(q - exact).max())
    assert 1e-10 < errors[0] < 1e-7
    assert 12 < errors[0] / errors[1] < 20  # 2^4 = 16


def test_free_tumble_direct_use_and_substeps() -> None:
    q0 = quat.random_uniform(np.random.default_rng(2), 2)
    omega = np.array([DS1_RATE, DS2_RATE])
    inertia = np.array(ASTROBEE_INERTIA) * 3.0  # scaling J changes nothing
    one = FreeTumble(q0, omega, ASTROBEE_INERTIA, 0.1)
    q1, w1 = one.advance(500)
    assert q1.shape == (2, 4, 500) and w1.shape == (2, 3, 500)
    np.testing.assert_array_equal(q1[:, :, 0], q0)
    np.testing.assert_allclose(w1[:, :, 0], omega, atol=1e-16)
    q3, w3 = FreeTumble(q0, omega, inertia, 0.1).advance(500)
    np.testing.assert_allclose(q3, q1, atol=1e-13)
    # four sub-steps of 0.025 s agree with one of 0.1 s to RK4 accuracy
    q4, w4 = FreeTumble(q0, omega, ASTROBEE_INERTIA, 0.1, substeps=4).advance(500)
    np.testing.assert_allclose(q4, q1, atol=1e-8)
    np.testing.assert_allclose(w4, w1, atol=1e-9)
    # chunked advance equals one piece
    chunked = FreeTumble(q0, omega, ASTROBEE_INERTIA, 0.1)
    parts = [chunked.advance(n) for n in (1, 2, 197, 300)]
    np.testing.assert_array_equal(np.concatenate([p[0] for p in parts], axis=2), q1)
    np.testing.assert_array_equal(np.concatenate([p[1] for p in parts], axis=2), w1)


def test_energy_and_momentum_known_values() -> None:
    inertia = np.array([2.0, 3.0, 4.0])
    identity = quat.IDENTITY
    assert kinetic_energy(identity, [1.0, 0.0, 0.0], inertia) == pytest.approx(1.0)
    np.testing.assert_allclose(angular_momentum_world(identity, [1.0, 0.0, 0.0], inertia), [2.0, 0.0, 0.0])
    # body x axis along world y: a world-y rate is a body-x rate
    q = quat.from_rotation_vector([0.0, 0.0, np.pi / 2])
    assert kinetic_energy(q, [0.0, 2.0, 0.0], inertia) == pytest.approx(0.5 * 2.0 * 4.0)
    np.testing.assert_allclose(angular_momentum_world(q, [0.0, 2.0, 0.0], inertia), [0.0, 4.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(angular_momentum_world(q, [2.0, 0.0, 0.0], inertia), [6.0, 0.0, 0.0], atol=1e-15)
    batch = angular_momentum_world(np.tile(q, (5, 1)), np.tile([0.0, 2.0, 0.0], (5, 1)), inertia)
    assert batch.shape == (5, 3)


# ---------------------------------------------------------------------------- translation
def test_constant_velocity_translation() -> None:
    scenario = get_scenario("ds1", n_steps=2000, velocity0=(0.01, -0.02, 0.003), position0_std=0.5)
    episodes = generate_episodes(scenario, [0, 5])
    t = episodes.times
    for b, seed in enumerate((0, 5)):
        truth = episodes.truth[b]
        r0 = np.array(scenario.position0) + 0.5 * stream(seed, "position0").standard_normal(3)
        np.testing.assert_allclose(truth[0, 4:7], r0, rtol=1e-15)
        np.testing.assert_allclose(truth[:, 4:7], r0 + t[:, None] * np.array(scenario.velocity0), rtol=1e-14)
        np.testing.assert_array_equal(truth[:, 10:13], np.broadcast_to(scenario.velocity0, (2000, 3)))
    assert not np.array_equal(episodes.truth[0, 0, 4:7], episodes.truth[1, 0, 4:7])


def test_default_position_is_fixed() -> None:
    truth = generate_episodes("ds1", [0, 1, 2]).truth
    np.testing.assert_array_equal(truth[:, :, 4:7], np.broadcast_to((10.9, -6.7, 4.9), truth[:, :, 4:7].shape))
    np.testing.assert_array_equal(truth[:, :, 10:13], 0.0)
