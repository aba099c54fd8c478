"""Episode generation: common random numbers, chunk and batch invariance, splits, errors."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.envs import Episodes, EpisodeStream, generate_episodes, initial_states
from fkn_bench.scenarios import get_scenario

# every effect active, a schedule that is not a divisor of the random-stream block (4096), and
# bursts longer than many chunks
BUSY = get_scenario(
    "ds1",
    n_steps=9000,
    measurement_every=3,
    dropout=0.1,
    burst_rate=0.01,
    burst_length=40,
    outlier_fraction=0.05,
    sign_flip_probability=0.3,
)


# exact comparisons in this file: the same seeded generation (numpy Generator streams are the same
# on any CPU) with element-wise arithmetic only; chunking, seeking, windows and seed order change
# which rows and steps are computed together, not the operations on each
def _equal(a: Episodes, b: Episodes) -> None:
    assert a.seeds == b.seeds and a.start == b.start and a.scenario == b.scenario
    np.testing.assert_array_equal(a.times, b.times)
    np.testing.assert_array_equal(a.truth, b.truth)
    np.testing.assert_array_equal(a.measurements, b.measurements)  # NaN compare equal here
    np.testing.assert_array_equal(a.valid, b.valid)


def _in_chunks(scenario, seeds, sizes) -> tuple[np.ndarray, ...]:
    source = EpisodeStream(scenario, seeds)
    parts = []
    sizes = iter(sizes)
    while source.index < scenario.n_steps:
        parts.append(source.advance(next(sizes)))
    assert source.advance(100)[0].shape == (0,)  # clipped at the end
    return tuple(np.concatenate(p, axis=0 if k == 0 else 1) for k, p in enumerate(zip(*parts)))


def _chunk_sizes(kind: str):
    if kind == "random":
        rng = np.random.default_rng(0)
        while True:
            yield int(rng.choice([1, 2, 3, 39, 40, 41, 500, 4095, 4096, 5000]))
    size = int(kind)
    while True:
        yield size


def test_episodes_shapes_and_times() -> None:
    episodes = generate_episodes("ds1", [4, 2])
    assert isinstance(episodes, Episodes)
    assert episodes.seeds == (4, 2) and episodes.start == 0
    assert (episodes.batch_size, episodes.n_steps) == (2, 16000)
    assert episodes.truth.shape == (2, 16000, 13) and episodes.measurements.shape == (2, 16000, 7)
    assert episodes.valid.shape == (2, 16000) and episodes.valid.dtype == bool
    assert episodes.truth.flags.c_contiguous and episodes.measurements.flags.c_contiguous
    np.testing.assert_allclose(episodes.times, np.arange(16000) * 0.1, rtol=1e-15)
    assert generate_episodes("ds1", 3).seeds == (0, 1, 2)


@pytest.mark.parametrize("sizes", ["random", "1", "7", "4096"])
def test_chunked_generation_equals_one_piece(sizes: str) -> None:
    seeds = [0, 1]
    scenario = BUSY.replace(n_steps=1200) if sizes == "1" else BUSY  # one step at a time: shorter
    whole = generate_episodes(scenario, seeds)
    times, truth, meas, valid = _in_chunks(scenario, seeds, _chunk_sizes(sizes))
    np.testing.assert_array_equal(times, whole.times)
    np.testing.assert_array_equal(truth, whole.truth)
    np.testing.assert_array_equal(meas, whole.measurements)
    np.testing.assert_array_equal(valid, whole.valid)
    assert 0 < whole.valid.mean() < 1 / 3


def test_chunked_free_tumble_equals_one_piece() -> None:
    scenario = get_scenario("tumble-fast", n_steps=1500, dropout=0.2)
    whole = generate_episodes(scenario, [5])
    times, truth, meas, valid = _in_chunks(scenario, [5], _chunk_sizes("random"))
    np.testing.assert_array_equal(truth, whole.truth)
    np.testing.assert_array_equal(meas, whole.measurements)
    np.testing.assert_array_equal(valid, whole.valid)


@pytest.mark.parametrize(
    "scenario", [BUSY.replace(n_steps=16000), get_scenario("tumble-fast", n_steps=1500)], ids=["busy", "free"]
)
def test_split_equals_slice_of_full_episode(scenario) -> None:
    seeds = [0, 3]
    full = generate_episodes(scenario, seeds)
    for name, (start, stop) in scenario.split_bounds().items():
        part = generate_episodes(scenario, seeds, split=name)
        assert part.start == start and part.n_steps == stop - start
        _equal(part, full.split(name))
        np.testing.assert_array_equal(part.truth, full.truth[:, start:stop])
        np.testing.assert_array_equal(part.measurements, full.measurements[:, start:stop])
        np.testing.assert_allclose(part.times, np.arange(start, stop) * scenario.dt, rtol=1e-15)


def test_ds1_test_split_bounds() -> None:
    test = generate_episodes("ds1", [0], split="test")
    assert test.start == 14400 and test.n_steps == 1600
    assert test.times[0] == pytest.approx(1440.0)
    assert test.valid.sum() == 160


def test_split_and_window_errors() -> None:
    test = generate_episodes("ds1", [0], split="test")
    with pytest.raises(ValueError, match="full-length episodes"):
        test.split("train")
    full = generate_episodes(get_scenario("ds1", n_steps=100), [0])
    with pytest.raises(ValueError, match="unknown split 'dev'; valid splits: train, val, test, full"):
        full.split("dev")
    with pytest.raises(ValueError, match="unknown split 'dev'; valid splits: train, val, test, full"):
        generate_episodes("ds1", [0], split="dev")
    window = full.window(10, 20)
    assert window.start == 10 and window.n_steps == 10
    np.testing.assert_array_equal(window.truth, full.truth[:, 10:20])


@pytest.mark.parametrize("scenario", [BUSY, get_scenario("tumble-slow", n_steps=800)], ids=["busy", "free"])
def test_batch_composition_does_not_change_an_episode(scenario) -> None:
    pair = generate_episodes(scenario, [3, 4])
    single = generate_episodes(scenario, [4])
    reversed_pair = generate_episodes(scenario, [4, 3])
    for other, row in ((single, 0), (reversed_pair, 0)):
        np.testing.assert_array_equal(pair.truth[1], other.truth[row])
        np.testing.assert_array_equal(pair.measurements[1], other.measurements[row])
        np.testing.assert_array_equal(pair.valid[1], other.valid[row])
    np.testing.assert_array_equal(pair.measurements[0], reversed_pair.measurements[1])
    assert not np.array_equal(pair.truth[0], pair.truth[1])


def test_common_random_numbers_share_truth() -> None:
    """Scenarios that differ only in the measurement model share the ground truth."""
    reference = generate_episodes("ds1", [0, 1])
    for name in ("ds1-noise5x", "ds1-gap100", "ds1-dropout", "ds1-flips"):
        other = generate_episodes(name, [0, 1])
        np.testing.assert_array_equal(other.truth, reference.truth)
    # the dynamics differ, the initial pose does not
    for name in ("ds2", "tumble-slow"):
        other = generate_episodes(get_scenario(name, n_steps=100), [0, 1])
        np.testing.assert_array_equal(other.truth[:, 0, :7], reference.truth[:, 0, :7])
    # same schedule: identical noise draws, scaled
    noisy = generate_episodes("ds1-noise5x", [0, 1])
    v = reference.valid
    np.testing.assert_array_equal(noisy.valid, v)
    np.testing.assert_allclose(
        noisy.measurements[v][:, 4:] - noisy.truth[v][:, 4:7],
        5 * (reference.measurements[v][:, 4:] - reference.truth[v][:, 4:7]),
        rtol=1e-9,
        atol=1e-13,
    )


def test_generation_is_deterministic() -> None:
    _equal(generate_episodes(BUSY, [7]), generate_episodes(BUSY, [7]))
    a, b = generate_episodes(BUSY, [7]), generate_episodes(BUSY, [8])
    assert not np.array_equal(a.measurements, b.measurements, equal_nan=True)


def test_seek() -> None:
    whole = generate_episodes(BUSY, [2])
    source = EpisodeStream(BUSY, [2])
    source.seek(5000)
    _, truth, meas, valid = source.advance(300)
    np.testing.assert_array_equal(truth, whole.truth[:, 5000:5300])
    np.testing.assert_array_equal(meas, whole.measurements[:, 5000:5300])
    np.testing.assert_array_equal(valid, whole.valid[:, 5000:5300])
    for bad in (-1, 9001):
        with pytest.raises(ValueError, match=r"step index must be in \[0, 9000\]"):
            source.seek(bad)


def test_seek_backwards_free_tumble() -> None:
    scenario = get_scenario("tumble-fast", n_steps=600)
    whole = generate_episodes(scenario, [1])
    source = EpisodeStream(scenario, [1])
    source.advance(500)
    source.seek(100)
    _, truth, _, _ = source.advance(50)
    np.testing.assert_array_equal(truth, whole.truth[:, 100:150])
    source.seek(400)
    _, truth, _, _ = source.advance(10)
    np.testing.assert_array_equal(truth, whole.truth[:, 400:410])


def test_initial_states() -> None:
    q, r, v = initial_states(get_scenario("ds1"), [0, 1, 2])
    assert q.shape == (3, 4) and r.shape == (3, 3) and v.shape == (3, 3)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)
    assert np.all(q[:, 0] >= 0)
    assert len({tuple(row) for row in q}) == 3
    fixed = get_scenario("ds1", attitude0=(0.0, 0.0, 0.0, 2.0), velocity0=(0.1, 0.0, 0.0))
    q, r, v = initial_states(fixed, [0, 1])
    np.testing.assert_array_equal(q, [[0.0, 0.0, 0.0, 1.0]] * 2)
    np.testing.assert_array_equal(v, [[0.1, 0.0, 0.0]] * 2)


@pytest.mark.parametrize(("seeds", "pattern"), [([], "at least one seed"), ([0, -1], "non-negative integer")])
def test_bad_seeds(seeds: list, pattern: str) -> None:
    with pytest.raises(ValueError, match=pattern):
        generate_episodes("ds1", seeds)


def test_body_frame_initial_rate_and_per_seed_inertia() -> None:
    """tumble-flip starts spinning about the body x axis from every attitude; tumble-inertia-error
    draws each seed's true inertia (reproducibly, within +-10%) while the scenario keeps the nominal."""
    from fkn_bench.envs.episodes import true_inertia
    from fkn_bench.geometry import quaternion as quat
    from fkn_bench.scenarios import ASTROBEE_INERTIA, get_scenario

    flip = generate_episodes("tumble-flip", [0, 1, 2], split="full").window(0, 2)
    body = quat.rotate(quat.conjugate(flip.truth[:, 0, :4]), flip.truth[:, 0, 7:10])
    np.testing.assert_allclose(body, np.tile((0.6, 0.1, 0.05), (3, 1)), atol=1e-12)
    scenario = get_scenario("tumble-inertia-error")
    inertia = true_inertia(scenario, [0, 1, 2, 3])
    assert np.all(np.abs(inertia / np.array(ASTROBEE_INERTIA) - 1.0) <= 0.1) and len({tuple(r) for r in inertia}) == 4
    np.testing.assert_array_equal(true_inertia(scenario, [2]), inertia[2:3])
    np.testing.assert_array_equal(true_inertia(get_scenario("tumble-fast"), [5, 6]), np.tile(ASTROBEE_INERTIA, (2, 1)))
    # the nominal inertia is wrong for the truth: a known-inertia prediction drifts from it
    from fkn_bench.models.rigid_body import RigidBodyModel

    episodes = generate_episodes(scenario, [0], split="test")
    truth = episodes.truth[0]
    nominal = RigidBodyModel(inertia=ASTROBEE_INERTIA).predict(truth[:-1].copy(), 0.1)
    exact = RigidBodyModel(inertia=tuple(inertia[0])).predict(truth[:-1].copy(), 0.1)
    assert np.abs(exact - truth[1:])[:, 7:10].max() < 1e-10 < 1e-6 < np.abs(nominal - truth[1:])[:, 7:10].max()


def test_tumble_flip_flips_within_the_test_split() -> None:
    from fkn_bench.geometry import quaternion as quat

    episodes = generate_episodes("tumble-flip", [0, 1], split="test")
    q, w = episodes.truth[..., :4], episodes.truth[..., 7:10]
    body_x = quat.rotate(quat.conjugate(q.reshape(-1, 4)), w.reshape(-1, 3))[:, 0].reshape(2, -1)
    assert all(np.any(np.diff(np.sign(row)) != 0) for row in body_x)  # the spin axis reverses


def test_episodes_index_by_sequence() -> None:
    """Issue 20, item 7: `load_episodes(...)[0]` failed; an Episodes is one batched object."""
    episodes = generate_episodes("ds1", [3, 4, 5], split="test")
    assert len(episodes) == 3
    first, last = episodes[0], episodes[-1]
    assert first.seeds == (3,) and last.seeds == (5,) and first.truth.shape == (1, episodes.n_steps, 13)
    np.testing.assert_array_equal(last.measurements[0], episodes.measurements[2])
    assert episodes[1:].seeds == (4, 5) and episodes[1:].valid.shape == (2, episodes.n_steps)
    with pytest.raises(IndexError, match="sequence 3 out of range: these episodes hold 3"):
        episodes[3]
    with pytest.raises(TypeError, match="integer or a slice"):
        episodes["a"]


def test_a_stated_prior_draws_each_episodes_own_truth() -> None:
    """Rate (axis uniform, magnitude log-uniform) and velocity drawn per seed from the seed's own
    streams: inside the stated range, different between seeds, the same for a seed whatever the
    batch or the measurement noise (common random numbers), and nothing drawn at zero spread."""
    from fkn_bench.envs.episodes import initial_rates, initial_states

    spin = get_scenario("ds1", name="spin", omega0_axis="uniform", omega0_magnitude=(0.02, 0.5), velocity0_std=0.01,
                        n_steps=50)
    rates = initial_rates(spin, range(200))
    magnitude = np.linalg.norm(rates, axis=1)
    assert (magnitude >= 0.02).all() and (magnitude <= 0.5).all() and len(np.unique(magnitude)) == 200
    assert np.abs(np.log(magnitude).mean() - np.log(0.1)) < 0.15  # log-uniform: mean of log = log(0.1)
    assert np.linalg.norm((rates / magnitude[:, None]).mean(axis=0)) < 0.2  # no preferred axis
    velocity = initial_states(spin, range(200))[2]
    assert 0.008 < velocity.std() < 0.012
    batch = generate_episodes(spin, [0, 3, 7])
    alone = generate_episodes(spin.replace(noise_scale=5.0), [3])
    np.testing.assert_array_equal(batch.truth[1], alone.truth[0])
    np.testing.assert_array_equal(batch.truth[:, 0, 7:10], initial_rates(spin, [0, 3, 7]))
    # zero spread: exactly omega0 and velocity0 (no draw), as before the prior existed
    ds1 = get_scenario("ds1")
    np.testing.assert_array_equal(initial_rates(ds1, [0, 1]), np.tile(ds1.omega0, (2, 1)))
    np.testing.assert_array_equal(initial_states(ds1, [0, 1])[2], np.zeros((2, 3)))
    fixed_axis = initial_rates(ds1.replace(omega0_magnitude=(0.05, 0.05), omega0_magnitude_distribution="uniform"), [4])
    np.testing.assert_allclose(fixed_axis[0], 0.05 * np.array(ds1.omega0) / np.linalg.norm(ds1.omega0), rtol=1e-15)


def test_an_episode_split_scenario_draws_each_split_from_its_own_seed_pool() -> None:
    """split_mode = "episodes": every split is whole episodes; train and val come from their own
    seed pools, so no episode (and no drawn truth) is shared with the test split, and the test
    split and the full episode of seed s are the same episode (what ``reset(seed=s)`` plays)."""
    from fkn_bench.scenarios import POOL_SIZE, SEED_POOLS, ConfigError

    spin = get_scenario("spin", n_steps=40)
    test, full = generate_episodes(spin, 3, split="test"), generate_episodes(spin, 3, split="full")
    train, val = generate_episodes(spin, 3, split="train"), generate_episodes(spin, 3, split="val")
    assert test.seeds == full.seeds == (0, 1, 2) and test.start == 0 and test.n_steps == 40
    np.testing.assert_array_equal(test.truth, full.truth)
    assert train.seeds == tuple(SEED_POOLS["train"] + i for i in range(3))
    assert val.seeds == tuple(SEED_POOLS["val"] + i for i in range(3))
    rates = [tuple(split.truth[:, 0, 7]) for split in (test, train, val)]
    assert len({r for split in rates for r in split}) == 9  # nine distinct truths
    with pytest.raises(ConfigError, match="outside the test pool"):
        generate_episodes(spin, [SEED_POOLS["train"]], split="test")
    with pytest.raises(ConfigError, match="outside the train pool"):
        generate_episodes(spin, [POOL_SIZE], split="train")
    with pytest.raises(ValueError, match="splits by episodes"):
        full.split("train")
    # the paper's time split is untouched: the seeds are the episodes, splits are pieces of them
    ds1 = get_scenario("ds1", n_steps=100)
    assert generate_episodes(ds1, 2, split="train").seeds == (0, 1)
