"""Seed chunks, grid order and cell keys."""

from __future__ import annotations

import pytest

from fkn_bench.harness import SEED_CHUNK, ResolvedEstimator, SimulatedSource, build_grid, chunk_seeds
from fkn_bench.harness.grid import estimator_label, path_name, variant_id
from fkn_bench.metrics import MetricSettings
from fkn_bench.scenarios import get_scenario


def test_chunks_are_consecutive_tens() -> None:
    assert SEED_CHUNK == 10
    chunks = chunk_seeds(range(25))
    assert chunks == [tuple(range(10)), tuple(range(10, 20)), tuple(range(20, 25))]
    assert chunk_seeds([7, 3, 5], size=2) == [(7, 3), (5,)]


@pytest.mark.parametrize("seeds", [[], [1, 1], [-1]])
def test_bad_seed_lists(seeds: list[int]) -> None:
    with pytest.raises(ValueError):
        chunk_seeds(seeds)


def test_grid_order_and_keys() -> None:
    sources = [SimulatedSource(get_scenario("ds1")), SimulatedSource(get_scenario("ds2"))]
    pairs = [ResolvedEstimator(name, source.label, fingerprint="f1" if (name, source.label) == ("a", "ds1") else "")
             for name in "ab" for source in sources]
    cells = build_grid(pairs, sources, range(15))
    assert [c.name for c in cells[:4]] == ["a/ds1/seeds-0-9", "b/ds1/seeds-0-9", "a/ds1/seeds-10-14", "b/ds1/seeds-10-14"]
    assert len(cells) == 8
    assert cells[0].resolved.fingerprint == "f1" and cells[1].resolved.fingerprint == ""
    assert cells[0].resolved is cells[2].resolved  # one resolution per pair, shared by its seed chunks
    key = cells[0].key()
    assert key["source"].startswith("simulated:ds1:") and key["seeds"] == list(range(10))
    other = build_grid(pairs[:1], sources[:1], range(15), settings=MetricSettings(cut=50))[0]
    assert other.key() != cells[0].key()


def test_source_key_follows_the_configuration() -> None:
    a = SimulatedSource(get_scenario("ds1"))
    b = SimulatedSource(get_scenario("ds1", noise_scale=2.0))
    assert a.key() != b.key() and a.label == b.label == "ds1"
    with pytest.raises(ValueError):
        SimulatedSource(get_scenario("ds1"), split="nope")


def test_path_names_are_injective_and_stay_in_their_directory() -> None:
    """Issue 34, finding 3: ``my fast``, ``my_fast`` and ``my/fast`` shared a cell; ``..`` escaped."""
    names = ["my fast", "my_fast", "my/fast", "my%2Ffast", "..", ".", ".hidden", "v1.2", "é", "manual-ekf", "A", "a"]
    encoded = [path_name(name) for name in names]
    assert len(set(encoded)) == len(names)
    assert encoded[:3] == ["my%20fast", "my_fast", "my%2Ffast"] and encoded[3] == "my%252Ffast"
    assert encoded[4:8] == ["%2E.", "%2E", "%2Ehidden", "v1.2"] and encoded[8] == "%C3%A9"
    assert path_name("ds1-noise5x") == "ds1-noise5x"  # the named scenarios keep their names
    for text in encoded:
        assert "/" not in text and not text.startswith(".")
    with pytest.raises(ValueError, match="empty name"):
        path_name("")


def test_the_variant_is_what_changes_the_numbers_but_the_estimator() -> None:
    cell = build_grid([ResolvedEstimator("a", "ds1")], [SimulatedSource(get_scenario("ds1"))], range(3))[0]
    key = cell.key()
    same = [{**key, "estimator_fingerprint": "retrained"}, {**key, "seeds": [7]}, {**key, "format_version": 9}]
    other = [{**key, "source": key["source"].replace(":test", ":val")}, {**key, "settings": {**key["settings"], "cut": 300}},
             {**key, "estimator_options": [["gate", 0.5]]}]
    assert {variant_id(k) for k in same} == {variant_id(key)}
    assert len({variant_id(k) for k in [key, *other]}) == 4 and len(variant_id(key)) == 12
    assert estimator_label("manual-ekf", [("gate", 0.5), ("parameters", "a.json")]) == \
        "manual-ekf (gate=0.5, parameters=a.json)"


def test_simulated_source_is_an_episode_source() -> None:
    from fkn_bench.harness import EpisodeSource

    source = SimulatedSource(get_scenario("ds1", n_steps=2000))
    assert isinstance(source, EpisodeSource)
    episodes = source.load([2, 5])
    assert episodes.seeds == (2, 5) and episodes.truth.shape == (2, 200, 13)
    assert not episodes.measurements.flags.writeable  # shared by the cells of a process
    assert source.describe()["config_hash"] == source.scenario.config_hash()
