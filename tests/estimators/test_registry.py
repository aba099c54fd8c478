"""The estimator registry: built-in names, unknown names, third-party registration, entry
points."""

from __future__ import annotations

import importlib.metadata
import sys
import types
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fkn_bench.estimators import (
    ENTRY_POINT_GROUP,
    Estimate,
    Estimates,
    Estimator,
    EstimatorSpec,
    KalmanEstimator,
    UnknownEstimatorError,
    estimator_names,
    estimator_specs,
    make_estimator,
    register_estimator,
)
from fkn_bench.estimators import registry
from fkn_bench.scenarios import Scenario, get_scenario

BUILTIN = ["manual-ekf", "manual-ukf", "manual-mekf", "oracle-ekf"]


@pytest.fixture(autouse=True)
def isolated_registry() -> Iterator[None]:
    """Snapshot the registry (with the built-ins loaded) and restore it afterwards, so that
    nothing registered here leaks into other tests."""
    registry._ensure_loaded()
    saved, loaded = dict(registry._REGISTRY), registry._LOADED
    yield
    registry._REGISTRY.clear()
    registry._REGISTRY.update(saved)
    registry._LOADED = loaded


class Constant(Estimator):
    """A third-party estimator: always the same state."""

    name = "constant"

    def __init__(self, *, scenario: Scenario | None = None, level: float = 0.0) -> None:
        self.scenario, self.level = scenario, level

    def estimate(self, measurements, mask, dt):  # noqa: ANN001, ANN201
        means = np.zeros(np.shape(mask) + (13,))
        means[..., 0] = 1.0
        return Estimates(means=means)

    def reset(self, *, dt: float) -> None:
        pass

    def step(self, observation: Any) -> Estimate:
        return Estimate(time=0.0, mean=np.eye(13)[0], native_covariance=np.eye(13), initialised=True, updated=False)

    def to_config(self) -> dict[str, Any]:
        return {"level": self.level}


def test_builtin_names_are_listed() -> None:
    names = estimator_names()
    assert names[:4] == BUILTIN
    specs = {spec.name: spec for spec in estimator_specs()}
    for name in BUILTIN:
        assert isinstance(specs[name], EstimatorSpec) and specs[name].description
        assert not specs[name].trainable
    assert isinstance(make_estimator("manual-ukf"), KalmanEstimator)


def test_unknown_name_lists_the_valid_ones() -> None:
    with pytest.raises(UnknownEstimatorError) as info:
        make_estimator("manual-pf")
    message = str(info.value)
    assert message.startswith("unknown estimator 'manual-pf'; valid estimators: ")
    for name in BUILTIN:
        assert name in message
    assert isinstance(info.value, KeyError)  # a KeyError whose str() is not quoted
    assert not message.startswith("'")


def test_register_a_third_party_estimator() -> None:
    spec = register_estimator("constant", Constant, description="always identity")
    assert isinstance(spec, EstimatorSpec)
    assert (spec.name, spec.factory, spec.description) == ("constant", Constant, "always identity")
    assert "constant" in estimator_names() and estimator_names()[:4] == BUILTIN
    scenario = get_scenario("ds2")
    made = make_estimator("constant", scenario=scenario, level=3.0)
    assert isinstance(made, Constant) and made.scenario is scenario and made.level == 3.0
    # duplicates are refused unless asked for
    with pytest.raises(ValueError, match=r"estimator 'constant' is already registered \(pass overwrite=True to replace it\)"):
        register_estimator("constant", Constant)
    with pytest.raises(ValueError, match="already registered"):
        register_estimator("manual-ekf", Constant)
    register_estimator("constant", lambda scenario=None, **o: Constant(level=-1.0), overwrite=True)
    assert make_estimator("constant").level == -1.0  # type: ignore[attr-defined]


def test_register_refuses_a_trainable_that_is_not_a_trainable() -> None:
    """A function passed as ``trainable=`` fails at registration, not at ``fit`` time."""
    with pytest.raises(TypeError, match="must be a fkn_bench.training.Trainable"):
        register_estimator("not-trainable", Constant, trainable=lambda options: options)
    assert "not-trainable" not in estimator_names()


def test_register_refuses_bad_names_and_factories() -> None:
    for name in ("", "my filter", "tab\tname", None):
        with pytest.raises(ValueError, match="non-empty string without spaces"):
            register_estimator(name, Constant)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="factory for estimator 'x' must be callable"):
        register_estimator("x", "not callable")  # type: ignore[arg-type]
    register_estimator("returns-dict", lambda scenario=None: {"not": "an estimator"})
    with pytest.raises(TypeError, match="factory of estimator 'returns-dict' returned dict, not an Estimator"):
        make_estimator("returns-dict")


def _fake_plugin(monkeypatch: pytest.MonkeyPatch, entries: list[importlib.metadata.EntryPoint]) -> None:
    module = types.ModuleType("fake_fkn_plugin")
    module.make_constant = lambda scenario=None, **options: Constant(scenario=scenario, level=7.0)  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "fake_fkn_plugin", module)
    groups: list[str] = []
    installed = importlib.metadata.entry_points  # fkn-bench's own: the built-ins

    def entry_points(*, group: str) -> list[importlib.metadata.EntryPoint]:
        groups.append(group)
        return [*installed(group=group), *[e for e in entries if e.group == group]]

    monkeypatch.setattr(importlib.metadata, "entry_points", entry_points)
    monkeypatch.setattr(registry, "_LOADED", False)
    monkeypatch.setattr(registry, "_fake_groups", groups, raising=False)


def test_entry_points_are_picked_up(monkeypatch: pytest.MonkeyPatch) -> None:
    entries = [
        importlib.metadata.EntryPoint("plugin-constant", "fake_fkn_plugin:make_constant", ENTRY_POINT_GROUP),
        importlib.metadata.EntryPoint("other-group", "fake_fkn_plugin:make_constant", "some.other.group"),
        # a plugin may not replace a built-in: skipped
        importlib.metadata.EntryPoint("manual-ekf", "fake_fkn_plugin:make_constant", ENTRY_POINT_GROUP),
    ]
    _fake_plugin(monkeypatch, entries)
    names = estimator_names()
    assert registry._fake_groups == [ENTRY_POINT_GROUP]  # type: ignore[attr-defined]
    assert "plugin-constant" in names and "other-group" not in names
    made = make_estimator("plugin-constant", scenario=get_scenario("ds1"))
    assert isinstance(made, Constant) and made.level == 7.0
    assert isinstance(make_estimator("manual-ekf"), KalmanEstimator)
    spec = {s.name: s for s in estimator_specs()}["plugin-constant"]
    assert spec.description == "plugin fake_fkn_plugin:make_constant"
    # loaded once: later calls do not query the entry points again
    estimator_names()
    assert registry._fake_groups == [ENTRY_POINT_GROUP]  # type: ignore[attr-defined]


def test_a_broken_entry_point_warns_and_the_rest_loads(monkeypatch: pytest.MonkeyPatch) -> None:
    entries = [
        importlib.metadata.EntryPoint("broken", "no_such_plugin_module_xyz:factory", ENTRY_POINT_GROUP),
        importlib.metadata.EntryPoint("plugin-constant", "fake_fkn_plugin:make_constant", ENTRY_POINT_GROUP),
    ]
    _fake_plugin(monkeypatch, entries)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        names = estimator_names()
    assert any("could not load estimator entry point 'broken'" in str(w.message) for w in caught)
    assert "broken" not in names and "plugin-constant" in names and names[:4] == BUILTIN


def test_the_built_ins_are_the_packages_own_entry_points(monkeypatch: pytest.MonkeyPatch) -> None:
    """The built-in estimators are found through the entry-point group, like a plugin's: a module
    per entry whose import registers them, fkn-bench's own loaded first and in name order (the
    ``-gated`` variants wrap the others); without fkn-bench's metadata installed none is found."""
    own = [e for e in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP) if registry._is_builtin(e)]
    assert [e.value for e in sorted(own, key=lambda e: e.name)] == [
        "fkn_bench.estimators.builtin", "fkn_bench.flexkalmannet.registration", "fkn_bench.baselines.registration",
        "fkn_bench.kalmannet.registration", "fkn_bench.estimators.gated", "fkn_bench.estimators.matched"]
    assert all(e.attr is None for e in own)  # modules, each registering several estimators
    plugin = importlib.metadata.EntryPoint("plugin-constant", "fake_fkn_plugin:make_constant", ENTRY_POINT_GROUP)
    monkeypatch.setattr(registry, "_LOADED", False)
    monkeypatch.setattr(importlib.metadata, "entry_points", lambda *, group: [plugin])  # no fkn-bench metadata
    with pytest.raises(RuntimeError, match="built-in estimators are entry points 'fkn_bench.estimators' of the "
                                           r"installed package, and none is installed: install fkn-bench \(pip install -e \."):
        estimator_names()
    assert registry._LOADED is False  # the next call looks again


def test_an_estimator_file_is_data_naming_only_known_classes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 34, finding 5: the file's "class" imported any module before any check ("this:X"
    printed the Zen of Python; a module in the working directory ran); now it must be the class of
    a loaded estimator, and its numbers JSON numbers."""
    import json

    from fkn_bench.estimators import EstimatorFileError, load_estimator, make_estimator

    good = json.loads(make_estimator("manual-ekf").save(tmp_path / "good.json").read_text())
    (tmp_path / "planted.py").write_text("import pathlib\npathlib.Path(__file__).with_name('ran').touch()\nclass X: pass\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "this", raising=False)
    cases = {
        "zen.json": ({"class": "this:X"}, r"zen\.json: cannot import estimator class this:X: an estimator file may name only "
                                          r".*known: .*fkn_bench\.estimators\.kalman:KalmanEstimator"),
        "planted.json": ({"class": "planted:X"}, r"planted\.json: cannot import estimator class planted:X"),
        "true.json": ({"config": {**good["config"], "r_std": [True] * 7}},
                      r"true\.json: invalid KalmanEstimator config: 'r_std' must be a list of finite numbers or none"),
        "text.json": ({"config": {**good["config"], "q_std": ["0.1"] * 13}}, r"text\.json: invalid KalmanEstimator config: 'q_std'"),
        "gate.json": ({"config": {**good["config"], "gate": float("nan")}}, r"gate\.json: .*'gate' must be a finite number or none"),
    }
    for name, (change, message) in cases.items():
        (tmp_path / name).write_text(json.dumps({**good, **change}))
        with pytest.raises(EstimatorFileError, match=message):
            load_estimator(tmp_path / name)
    assert "this" not in sys.modules and "planted" not in sys.modules and not (tmp_path / "ran").exists()
    assert "Beautiful is better" not in capsys.readouterr().out
    assert load_estimator(tmp_path / "good.json").to_config() == good["config"]
