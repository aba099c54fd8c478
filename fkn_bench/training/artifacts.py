"""Learned-parameter artefacts: the small JSON files that let trained estimators run out of the box.

``fkn-bench train`` writes one next to its checkpoint, and the project commits one per trained
estimator and model family as ``<package>/params/<estimator>-<family>.json``, in the package that
the estimator's registration names (``params_package``, :mod:`fkn_bench.estimators.registry`:
``fkn_bench/flexkalmannet/params``, ``fkn_bench/kalmannet/params``, ``baselines/params``), with the
provenance of the run that produced it:

``format``, ``format_version``, ``estimator``, ``family`` (the scenario family it applies to,
e.g. ds1), ``scenario`` (training scenario name and config hash), ``estimator_config`` (a
:class:`~fkn_bench.estimators.KalmanEstimator` config: variant and noise), ``parameters``
(the learned values with labels and units), ``training`` (config, best epoch, losses, time,
test metrics) and ``provenance`` (package and library versions, git commit, machine, command).

:class:`TrainedKalmanEstimator` runs from such a file, and :func:`artifact_factory` is the registry
factory of every trained estimator: the committed artefact of the scenario's model family, or
``parameters=PATH``.
"""

from __future__ import annotations

import datetime as _dt
import re
import sys
from importlib import resources
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import torch

from fkn_bench.config_values import check_arguments, init_annotations
from fkn_bench.estimators.kalman import KalmanEstimator
from fkn_bench.io import read_json, write_json_atomic
from fkn_bench.models.registry import DEFAULT_MODEL
from fkn_bench.scenarios import Scenario
from fkn_bench.training.checkpoint import checked_document

__all__ = [
    "ARTIFACT_FORMAT",
    "ARTIFACT_FORMAT_VERSION",
    "ArtifactError",
    "artifact_path",
    "committed_artifact_path",
    "seed_artifact_path",
    "seed_study",
    "training_seed_artifact",
    "SEEDS_DIR",
    "params_dir",
    "artifact_label",
    "install_artifact",
    "resolve_artifact_label",
    "weights_of_artifact",
    "write_artifact",
    "read_artifact",
    "run_provenance",
    "deployed_estimator_config",
    "TrainedKalmanEstimator",
    "artifact_factory",
    "artifact_family",
    "committed_artifact",
    "trained_network",
    "DEFAULT_FAMILY",
]

ARTIFACT_FORMAT = "fkn-bench-learned-parameters"
ARTIFACT_FORMAT_VERSION = 1


class ArtifactError(ValueError):
    """A learned-parameter file that is missing, corrupt or of another format/version."""


def params_dir(package: str) -> Path:
    """The ``params/`` folder of the (importable) package ``package`` in this installation."""
    return Path(str(resources.files(package))) / "params"


def _params_dirs() -> dict[str, Path]:
    """``{package: its params folder}`` for every package that a registered estimator names as
    the owner of its committed parameter files, in the order of registration."""
    from fkn_bench.estimators.registry import estimator_specs

    packages = dict.fromkeys(s.params_package for s in estimator_specs() if s.params_package is not None)
    return {package: params_dir(package) for package in packages}


def artifact_path(estimator: str, family: str) -> Path:
    """Where the committed artefact of ``estimator`` for model family ``family`` lives: the
    ``params/`` folder of the package its registration names (``params_package``). Raises
    :class:`ArtifactError` for an estimator registered without one."""
    from fkn_bench.estimators.registry import estimator_spec

    package = estimator_spec(estimator).params_package
    if package is None:
        raise ArtifactError(f"estimator {estimator!r} has no committed parameter files (its registration names no "
                            "params_package): pass parameters=PATH")
    return params_dir(package) / f"{estimator}-{family}.json"


SEEDS_DIR = "seeds"
"""The folder, inside a params folder, of the training seeds a seed study did not choose
(:mod:`fkn_bench.training.seeds`)."""


def seed_artifact_path(estimator: str, family: str, seed: int) -> Path:
    """Where the artefact of training seed ``seed`` of a seed study of ``estimator`` on
    ``family`` lives when the study did not choose it: ``params/seeds/<estimator>-<family>-seed<K>.json``
    beside the committed artefact (:func:`artifact_path`)."""
    return artifact_path(estimator, family).parent / SEEDS_DIR / f"{estimator}-{family}-seed{int(seed)}.json"


def training_seed_artifact(path: str | Path, estimator: str, family: str, seed: int) -> Path:
    """The artefact of training seed ``seed`` of the seed study that produced the committed
    artefact ``path`` of ``estimator`` for ``family``: ``path`` itself for the chosen seed, else
    its file under ``params/seeds/``. Raises :class:`ArtifactError` for an artefact trained with one
    seed, a seed the study did not train (naming those it did) or a missing seed file."""
    study = _seed_study_of(read_artifact(path))
    if study is None:
        raise ArtifactError(f"{path} was trained with one seed (its 'training' has no seed_study): training_seed= "
                            f"needs a seed study, `fkn-bench train --estimator {estimator} ... --seeds 0 1 2 "
                            "--write-artifact`")
    trained = [int(r["seed"]) for r in study.get("runs", ()) if r.get("status") == "ok"]
    if int(seed) not in trained:
        raise ArtifactError(f"training_seed={seed}: the seed study of {path} trained seeds "
                            f"{', '.join(map(str, trained))}")
    if int(seed) == int(study["chosen_seed"]):
        return Path(path)
    target = seed_artifact_path(estimator, family, seed)
    if not target.is_file():
        raise ArtifactError(f"training_seed={seed}: {target} is missing (the seed study of {path} trained it)")
    return target


def _seed_study_of(document: Mapping[str, Any]) -> dict[str, Any] | None:
    study = (document.get("training") or {}).get("seed_study")
    return study if isinstance(study, dict) else None


def seed_study(path: str | Path) -> dict[str, Any] | None:
    """The ``training.seed_study`` of the artefact ``path`` (None: trained with one seed, or an
    unreadable file)."""
    try:
        return _seed_study_of(read_artifact(path))
    except ArtifactError:
        return None


def committed_artifact_path(estimator: str, family: str) -> Path | None:
    """The committed artefact of ``estimator`` for ``family`` when there is one; None for an
    estimator that is not registered, declares no ``params_package`` or has no file for
    ``family`` (for tables that leave such estimators out)."""
    from fkn_bench.estimators.registry import UnknownEstimatorError

    try:
        path = artifact_path(estimator, family)
    except (ArtifactError, UnknownEstimatorError):
        return None
    return path if path.is_file() else None


_LABEL = re.compile(r"(?P<package>[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*)/params/(?P<file>.+)")
"""An :func:`artifact_label`: ``<package>/params/<file>``."""


def resolve_artifact_label(label: str | Path) -> Path:
    """The file an :func:`artifact_label` names, in this installation: ``<package>/params/<file>``
    in the params folder of that package when it declares committed files and holds ``file``;
    else (a label written before the file moved to another package, e.g.
    ``fkn_bench.baselines/params/kalmannet-ds1.weights.pt`` before the learned estimators' files
    moved to their own packages) in the one declared params folder that holds it. Anything else
    is a path."""
    match = _LABEL.fullmatch(str(label))
    if match is None:
        return Path(label)
    package, name = match["package"], match["file"]
    dirs = _params_dirs()
    if package in dirs and (dirs[package] / name).is_file():
        return dirs[package] / name
    holders = [folder / name for folder in dirs.values() if (folder / name).is_file()]
    if len(holders) == 1:
        return holders[0]
    return dirs[package] / name if package in dirs else Path(label)


def artifact_label(path: str | Path) -> str:
    """How an estimator's config names the artefact it was built from: ``<package>/params/<file>``
    for a committed one (e.g. ``fkn_bench.kalmannet/params/kalmannet-ds1.weights.pt``: independent
    of where the package is installed, so that configuration fingerprints, and with them the
    committed leaderboards, do not change with the checkout's location), else the path as the user
    gave it."""
    try:
        resolved = Path(path).resolve()
    except OSError:
        return str(path)
    for package, folder in _params_dirs().items():
        try:
            relative = resolved.relative_to(folder.resolve())
        except (OSError, ValueError):
            continue
        return f"{package}/params/{relative.as_posix()}"
    return str(path)


def portable_command(argv: list[str]) -> list[str]:
    """``argv`` as anyone can rerun it from the repository's root: the program by its name
    (``fkn-bench``, not the path of one machine's virtual environment), and every argument that
    names a file inside the repository (or the installed package's folder) by its path relative to
    it (``fkn_bench/kalmannet/params/kalmannet-ds1.json``). Other arguments are kept as given."""
    root = Path(__file__).resolve().parents[2]
    command = [Path(argv[0]).name if argv else "fkn-bench"]
    for argument in argv[1:]:
        try:
            relative = Path(argument).resolve().relative_to(root) if Path(argument).exists() else None
        except (OSError, ValueError):
            relative = None
        command.append(relative.as_posix() if relative is not None else argument)
    return command


def run_provenance() -> dict[str, Any]:
    """Versions, git commit, machine, command line (:func:`portable_command`) and UTC time of this
    process."""
    from fkn_bench.provenance import environment

    return {
        **environment(),
        "command": portable_command(sys.argv),
        "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }


def write_artifact(
    path: str | Path,
    *,
    estimator: str,
    family: str,
    scenario: dict[str, Any],
    estimator_config: dict[str, Any],
    parameters: dict[str, Any],
    training: dict[str, Any],
) -> Path:
    """Write an artefact (see module docstring) atomically, with this process's provenance."""
    fields = dict(estimator=estimator, family=family, scenario=scenario, estimator_config=estimator_config,
                  parameters=parameters, training=training)
    return write_json_atomic(path, {"format": ARTIFACT_FORMAT, "format_version": ARTIFACT_FORMAT_VERSION, **fields,
                                    "provenance": run_provenance()})


WEIGHTS_SUFFIX = ".weights.pt"
"""Committed network weights sit beside their artefact as ``<estimator>-<family>.weights.pt``."""

_WEIGHTS_KEYS = ("estimator", "config", "scenario", "deployed", "state_dict", "best_epoch", "provenance")


def install_artifact(artifact: str | Path, estimator: str, family: str, *, target: str | Path | None = None,
                     training_extra: Mapping[str, Any] | None = None) -> Path:
    """Install the ``parameters.json`` of a training run as the committed artefact of
    ``estimator`` for ``family`` (:func:`artifact_path`, or ``target``: e.g. a training seed's
    :func:`seed_artifact_path`); returns its path. ``training_extra`` is merged into the
    artefact's ``training`` (a seed study's record).

    An artefact of constant parameters is copied. One that deploys a network (KalmanNet, Recursive
    KalmanNet: its ``estimator_config`` names a training ``checkpoint``, or installed ``weights``)
    gets its weights file beside it,
    ``<estimator>-<family>.weights.pt``: the checkpoint without the optimiser, scheduler, RNG and
    data state (a checkpoint document, read with ``torch.load(weights_only=True)``), and the
    artefact's ``estimator_config`` becomes ``{"weights": <file name>, "weights_sha256": <hex>}``,
    so that a weights file that does not match its artefact is refused. Both are written atomically.
    """
    import hashlib

    from fkn_bench.io import write_bytes_atomic
    from fkn_bench.training.checkpoint import load_checkpoint, save_checkpoint

    document = read_artifact(artifact)
    target = Path(target) if target is not None else artifact_path(estimator, family)
    if training_extra:
        document["training"] = {**(document.get("training") or {}), **training_extra}
    network = bool({"checkpoint", "weights"} & set(document["estimator_config"]))
    if not network and not training_extra:
        write_bytes_atomic(target, Path(artifact).read_bytes())
        return target
    if network:
        full = load_checkpoint(weights_of_artifact(artifact, estimator))
        weights = target.with_name(target.name.removesuffix(".json") + WEIGHTS_SUFFIX)
        save_checkpoint(weights, {k: full[k] for k in _WEIGHTS_KEYS if k in full})
        digest = hashlib.sha256(weights.read_bytes()).hexdigest()
        document["estimator_config"] = {"weights": weights.name, "weights_sha256": digest}
    fields = {k: document[k] for k in ("estimator", "family", "scenario", "estimator_config", "parameters", "training")
              if k in document}
    write_json_atomic(target, {"format": ARTIFACT_FORMAT, "format_version": ARTIFACT_FORMAT_VERSION, **fields,
                               "provenance": document.get("provenance") or run_provenance()})
    return target


def weights_of_artifact(path: str | Path, estimator: str) -> Path:
    """The network weights a ``parameters.json`` of ``estimator`` deploys: the installed
    ``weights`` file beside it (its SHA-256 checked), else the training ``checkpoint`` it names
    (as written, or beside it when the run directory was moved). Raises :class:`ArtifactError`
    naming the file and the problem."""
    import hashlib

    document = read_artifact(path)
    if document["estimator"] != estimator:
        raise ArtifactError(f"{path} holds {document['estimator']!r} parameters, not {estimator}'s")
    config = document["estimator_config"]
    if "weights" in config:
        weights = Path(path).parent / str(config["weights"])
        if not weights.is_file():
            raise ArtifactError(f"{path}: its weights file {weights} is missing")
        if hashlib.sha256(weights.read_bytes()).hexdigest() != config.get("weights_sha256"):
            raise ArtifactError(f"{weights} does not match {path} (SHA-256 differs): corrupt or replaced")
        return weights
    named = config.get("checkpoint")
    if named is not None and Path(named).is_file():
        return Path(named)
    beside = Path(path).parent / "checkpoint.pt"
    if beside.is_file():
        return beside
    raise ArtifactError(f"{path}: the {estimator} checkpoint it names ({named}) is not there, nor {beside}")


def read_artifact(path: str | Path) -> dict[str, Any]:
    """Read and check an artefact; raises :class:`ArtifactError` naming the file and problem."""
    if not str(path).strip():
        raise ArtifactError("the learned-parameter file name is empty (parameters=PATH names a parameters.json)")
    path = Path(path)
    try:
        document = read_json(path)
    except FileNotFoundError:
        raise ArtifactError(f"learned-parameter file not found: {path}") from None
    except ValueError as exc:  # a directory, unreadable, not UTF-8 or not JSON (read_json names the file)
        raise ArtifactError(str(exc)) from None
    return checked_document(document, path, ARTIFACT_FORMAT, ARTIFACT_FORMAT_VERSION, "a learned-parameter file",
                            ("estimator", "family", "estimator_config", "parameters"), ArtifactError)


def deployed_estimator_config(model: Any, settings: Any) -> dict[str, Any]:
    """KalmanEstimator config (variant, process model and noise matrices or stds) of a trained
    :class:`~fkn_bench.training.NoiseModel`'s deployed parameters (``settings``: the
    :class:`~fkn_bench.training.TrainConfig` it was trained with)."""
    with torch.no_grad():
        noise = model.parameter_set.to_noise(model.deployed_raw())
    config: dict[str, Any] = {"variant": settings.variant}
    if settings.process_model != DEFAULT_MODEL:
        inertia = settings.inertia
        config.update(model=settings.process_model, inertia=None if inertia is None else list(inertia))
    for entry, matrix in (("q", noise.process), ("r", noise.measurement), ("p0", noise.initial)):
        m = matrix.detach().to(torch.float64).numpy()
        if np.count_nonzero(m - np.diag(np.diag(m))) == 0:
            config[f"{entry}_std"] = np.sqrt(np.diag(m)).tolist()
        else:
            config[f"{entry}_cov"] = m.tolist()
    return config


class TrainedKalmanEstimator(KalmanEstimator):
    """A :class:`~fkn_bench.estimators.KalmanEstimator` with trained constant parameters and the
    ``metadata`` (training and provenance) of the fit that produced them. Subclasses name the
    estimator (``default_name``) and describe it by name (``descriptions``)."""

    default_name: ClassVar[str] = "trained-kalman"
    descriptions: ClassVar[dict[str, str]] = {}

    def __init__(self, *, metadata: Mapping[str, Any] | None = None, **config: Any) -> None:
        config.setdefault("name", self.default_name)
        config.setdefault("description", self.descriptions.get(config["name"], ""))
        super().__init__(**config)
        self.metadata = dict(metadata or {})

    @classmethod
    def from_artifact(cls, path: str | Path, *, name: str | None = None, gate: float | None = None) -> TrainedKalmanEstimator:
        """The estimator of an artefact (``name``: the estimator it must hold, e.g. the registry
        name being built; ``gate``: a chi-square innovation gate level over the artefact's, see
        :class:`~fkn_bench.estimators.KalmanEstimator`). Complete or rejected: an artefact of
        another estimator, one whose ``estimator_config`` lacks the variant or any of ``Q``,
        ``R``, ``P0`` (as ``*_std`` or ``*_cov``), one whose values are not of the kinds the
        estimator takes (:mod:`fkn_bench.config_values`: a standard deviation is a finite JSON
        number, never ``true`` or ``"0.1"``) or do not build a filter (e.g. a standard deviation
        out of range) raises :class:`ArtifactError` naming the file and the key."""
        document = read_artifact(path)
        if name is not None and document["estimator"] != name:
            raise ArtifactError(f"{path} holds {document['estimator']!r} parameters, not {name}'s")
        config = document["estimator_config"]
        if not isinstance(config, dict):
            raise ArtifactError(f"{path}: 'estimator_config' must be an object (got {type(config).__name__})")
        missing = [entry for entry in ("q", "r", "p0") if f"{entry}_std" not in config and f"{entry}_cov" not in config]
        if "variant" not in config:
            missing.insert(0, "variant")
        if missing:
            keys = ", ".join(k if k == "variant" else f"{k}_std (or {k}_cov)" for k in missing)
            raise ArtifactError(f"{path}: 'estimator_config' lacks {keys}: an incomplete parameter file is not "
                                "completed with defaults")
        try:  # numbers are JSON numbers: `true` or "0.1" is no standard deviation
            check_arguments(init_annotations(cls), config, "'estimator_config'")
        except ValueError as exc:
            raise ArtifactError(f"{path}: {exc}") from None
        metadata = {k: document.get(k) for k in ("family", "scenario", "training", "provenance")}
        metadata["artifact"] = artifact_label(path)
        gated = {} if gate is None else {"gate": gate}
        try:
            return cls(metadata=metadata, **{**config, **gated, "name": name or document["estimator"]})
        except (TypeError, ValueError) as exc:
            raise ArtifactError(f"{path}: 'estimator_config' does not build a filter: {exc}") from None

    def to_config(self) -> dict[str, Any]:
        return {**super().to_config(), "metadata": self.metadata}

    CONFIG_KEYS = KalmanEstimator.CONFIG_KEYS | {"metadata"}  # from_config passes metadata= to __init__


DEFAULT_FAMILY = "default"
"""The family of the artefact trained on a mixture of motions (constant rate and free tumbling),
used where no named scenario's family applies: recordings, user scenarios, no scenario."""


def artifact_family(name: str, scenario: Scenario | None) -> str:
    """The model family whose committed artefact of ``name`` runs on ``scenario``: a built-in
    scenario's own family; for anything else (a recording, a user scenario, no scenario) the
    mixture-trained :data:`DEFAULT_FAMILY` when it is committed, else the scenario's family
    (``ds1`` without a scenario)."""
    from fkn_bench.scenarios import get_scenario, scenario_names

    if scenario is not None and scenario.name in scenario_names():
        if get_scenario(scenario.name).config_hash() == scenario.config_hash():
            return scenario.model_family
    if artifact_path(name, DEFAULT_FAMILY).is_file():
        return DEFAULT_FAMILY
    return scenario.model_family if scenario is not None else "ds1"


def committed_artifact(name: str, scenario: Scenario | None, label: str | None = None, *, swept: bool = False,
                       training_seed: int | None = None) -> Path:
    """The committed artefact of estimator ``name`` for ``scenario`` (:func:`artifact_family`);
    raises :class:`ArtifactError` with the command that trains and installs it (``label``: how the
    message names the estimator, default ``name``; ``swept``: settings found by ``fkn-bench
    sweep --space <name>``, not trained). ``training_seed``: that seed of the artefact's seed study
    (:func:`training_seed_artifact`)."""
    from fkn_bench.scenarios import scenario_names

    family = artifact_family(name, scenario)
    path = artifact_path(name, family)
    if not path.is_file():
        named = family in scenario_names()
        if swept:
            data = f"--scenario {family}" if named else "--scenario S"
            raise ArtifactError(f"no tuned {label or name} settings for model family '{family}' ({path}): sweep them "
                                f"with `fkn-bench sweep --space {name} {data} --write-artifact`")
        data = f"--scenario {family}" if named else f"--scenario S1 --scenario S2 ... --family {family}"
        raise ArtifactError(f"no trained {label or name} for model family '{family}' ({path}): train one with "
                            f"`fkn-bench train --estimator {name} {data} --write-artifact`")
    return path if training_seed is None else training_seed_artifact(path, name, family, training_seed)


def trained_network(
    estimator: str, label: str, scenario: Scenario | None, checkpoint: str | Path | None, parameters: str | Path | None,
    training_seed: int | None = None,
) -> Path:
    """The network weights a registry factory of ``estimator`` loads (``label``: how messages name
    it): ``checkpoint=PATH``, the ``parameters=PATH`` of a training run, or the committed artefact
    of the scenario's model family (:func:`artifact_family`: a recording or a user scenario gets
    the ``default`` family's when one is committed), or its seed study's ``training_seed``."""
    if sum(x is not None for x in (checkpoint, parameters, training_seed)) > 1:
        raise ValueError("give one of checkpoint=, parameters= and training_seed=, not several")
    if checkpoint is not None:
        return Path(checkpoint)
    return weights_of_artifact(parameters or committed_artifact(estimator, scenario, label, training_seed=training_seed),
                               estimator)


def artifact_factory(name: str, cls: type[TrainedKalmanEstimator] = TrainedKalmanEstimator) -> Callable[..., Any]:
    """Registry factory of the trained estimator ``name``: the committed artefact of the
    scenario's model family (see :func:`artifact_family`), or ``parameters=PATH`` (a
    ``parameters.json`` written by ``fkn-bench train``); ``gate``: a chi-square innovation gate
    level (:class:`~fkn_bench.estimators.KalmanEstimator`); ``training_seed``: that seed of the
    committed artefact's seed study (:mod:`fkn_bench.training.seeds`)."""

    def factory(scenario: Scenario | None = None, *, parameters: str | Path | None = None,
                gate: float | None = None, training_seed: int | None = None) -> TrainedKalmanEstimator:
        if parameters is not None and training_seed is not None:
            raise ValueError("give either parameters= or training_seed=, not both")
        path = parameters if parameters is not None else committed_artifact(name, scenario, training_seed=training_seed)
        return cls.from_artifact(path, name=name, gate=gate)

    factory.__name__ = f"{name.replace('-', '_')}_factory"
    return factory
