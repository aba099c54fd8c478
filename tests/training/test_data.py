"""Training windows of a scenario's data set."""

from __future__ import annotations

import pytest
import torch

from fkn_bench.envs import generate_episodes
from fkn_bench.scenarios import get_scenario
from fkn_bench.training import TrainingData

SHORT = get_scenario("ds1", n_steps=4000)


def test_windows_are_consecutive_samples_of_the_train_split() -> None:
    data = TrainingData(SHORT, window=500, stride=250, train_measurement_every=1)
    full = generate_episodes(SHORT.replace(measurement_every=1), [SHORT.dataset_seed], split="train")
    assert data.n_windows == (3200 - 500) // 250 + 1
    # exact: windows are copies of the same seeded generation
    assert torch.equal(data.train.truth[1], torch.as_tensor(full.truth[0, 250:750]))
    assert torch.equal(data.train.mask[3], torch.as_tensor(full.valid[0, 750:1250]))
    assert bool(data.train.mask.all())  # a measurement every step


def test_validation_uses_the_scenario_schedule_and_positions_are_normalised() -> None:
    data = TrainingData(SHORT, window=400, train_measurement_every=1)
    assert data.val.measurements.shape == (1, 400, 7)
    assert data.val.mask.float().mean().item() == pytest.approx(0.1)
    assert torch.allclose(data.position_mean, torch.tensor(SHORT.position0, dtype=torch.float64), atol=0.02)
    assert torch.allclose(data.position_std, torch.full((3,), 0.1, dtype=torch.float64), rtol=0.1)


def test_batches_cover_every_window_once_in_a_seeded_order() -> None:
    data = TrainingData(SHORT, window=400, stride=200)
    seen = [b.truth[:, 0, 4:7] for b in data.batches(4, torch.Generator().manual_seed(0))]
    again = [b.truth[:, 0, 4:7] for b in data.batches(4, torch.Generator().manual_seed(0))]
    assert sum(len(s) for s in seen) == data.n_windows
    assert all(torch.equal(a, b) for a, b in zip(seen, again))  # exact: same seeded order, copies


def test_bad_windows_are_refused() -> None:
    with pytest.raises(ValueError, match="window"):
        TrainingData(SHORT, window=1)
    with pytest.raises(ValueError, match="fewer than one window"):
        TrainingData(SHORT, window=5000)


def test_a_mixture_holds_the_windows_and_val_splits_of_every_scenario() -> None:
    fast = get_scenario("tumble-fast", n_steps=4000)
    one, two = TrainingData(SHORT, window=800), TrainingData(fast, window=800)
    mixed = TrainingData([SHORT, fast], window=800)
    assert mixed.scenario.name == "ds1" and [s.name for s in mixed.scenarios] == ["ds1", "tumble-fast"]
    assert mixed.n_windows == one.n_windows + two.n_windows
    torch.testing.assert_close(mixed.train.truth, torch.cat((one.train.truth, two.train.truth)), rtol=0, atol=0)
    torch.testing.assert_close(mixed.val.truth, torch.cat((one.val.truth, two.val.truth)), rtol=0, atol=0)
    assert mixed.describe()["scenario"] == "ds1+tumble-fast" and len(mixed.describe()["config_hash"]) == 2
    with pytest.raises(ValueError, match="one dt"):
        TrainingData([get_scenario("ds1"), get_scenario("ds1").replace(name="fast", dt=0.05)], window=800)


def test_a_prior_family_trains_on_its_train_pool_and_validates_on_its_val_pool() -> None:
    """An episode-split scenario: at least PRIOR_EPISODES episodes per pool, windows of whole
    train-pool episodes, validation over val-pool episodes, never a test episode."""
    from fkn_bench.envs.episodes import initial_rates
    from fkn_bench.scenarios import SEED_POOLS
    from fkn_bench.training.data import PRIOR_EPISODES

    spin = get_scenario("spin", n_steps=200)
    data = TrainingData(spin, window=100, episodes=4)
    assert data.n_windows == 2 * PRIOR_EPISODES and data.val.batch_size == PRIOR_EPISODES
    assert data.describe()["episodes_per_pool"] == {"spin": PRIOR_EPISODES}
    trained = initial_rates(spin, [SEED_POOLS["train"] + i for i in range(PRIOR_EPISODES)])
    validated = initial_rates(spin, [SEED_POOLS["val"] + i for i in range(PRIOR_EPISODES)])
    torch.testing.assert_close(data.train.truth[::2, 0, 7:10], torch.as_tensor(trained), rtol=0, atol=0)
    torch.testing.assert_close(data.val.truth[:, 0, 7:10], torch.as_tensor(validated), rtol=0, atol=0)
    tested = generate_episodes(spin, 50, split="test").truth[:, 0, 7:10]
    assert not set(map(tuple, tested.tolist())) & set(map(tuple, trained.tolist() + validated.tolist()))
