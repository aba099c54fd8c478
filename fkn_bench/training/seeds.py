"""Training-seed studies: one configuration trained with several seeds, and the committed
artefact chosen among them before any test score is read.

A learned filter's test score is one draw from the distribution of training outcomes: the seed
fixes the network's initialisation and the order of the training windows, and on KalmanNet the
spread between seeds reaches 10% (Revach et al., IEEE TSP 2022, and the KalmanNet_TSP issues
that report runs which do not reproduce). :func:`train_seeds` trains the same configuration once
per seed, each into ``OUT/seed-<K>/`` (a complete ``fkn-bench train`` run directory), and records
the study in ``OUT/seed_study.json`` and ``OUT/seed_study.csv``.

**The choice.** The committed artefact is the run of the *median validation* seed
(:func:`median_seed`): the seeds sorted by their best-epoch validation 13-state RMSE (ties by
seed), the middle one, the lower middle for an even count. Validation only: the test split's
RMSE, which every run also reports, is recorded and never read by the choice, so the committed
row is a typical training outcome, not the luckiest one on the test data. A seed whose training
failed (a diverged loss, no epoch completed) is recorded with its error and takes no part.

:func:`install_seed_study` (``fkn-bench train --seeds ... --write-artifact``) installs the chosen
run as ``<estimator>-<family>.json`` with the study in its ``training.seed_study`` and every other
seed's run under ``params/seeds/`` (:func:`~fkn_bench.training.artifacts.seed_artifact_path`),
so that the harness can score each training seed on the test episodes
(``training_seed=K``, :mod:`fkn_bench.harness.estimators`) and the leaderboards show the spread
over training seeds beside the spread over test episodes.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from fkn_bench.io import write_json_atomic, write_text_atomic
from fkn_bench.scenarios import Scenario

__all__ = ["SEED_STUDY_FILE", "SEED_RULE", "SeedRun", "SeedStudy", "median_seed", "train_seeds", "install_seed_study"]

SEED_STUDY_FILE = "seed_study.json"
SEED_RULE = "median validation 13-state RMSE (equal values ordered by seed; an even count: the lower middle)"
"""How the committed seed is chosen (module docstring), as the study records it."""


@dataclass(frozen=True)
class SeedRun:
    """One seed's training run.

    Attributes:
        seed: the training seed (network initialisation and window order).
        status: ``"ok"`` or ``"failed"``.
        val_rmse: validation 13-state RMSE at the best epoch (the value the choice reads;
            NaN for a failed run).
        best_epoch, epochs_run, seconds: as ``fkn-bench train`` reports them.
        test_rmse: 13-state RMSE of the deployed parameters on the test split (recorded, never
            read by the choice; None when the run did not report one).
        out: the run directory.
        error: why a failed run failed.
    """

    seed: int
    status: str
    val_rmse: float
    best_epoch: int = 0
    epochs_run: int = 0
    seconds: float = 0.0
    test_rmse: float | None = None
    out: str = ""
    error: str | None = None


def median_seed(values: Mapping[int, float]) -> int:
    """The seed whose value is the median of ``values`` (``{seed: validation RMSE}``, finite
    values only): sorted by ``(value, seed)``, the middle entry, the lower middle for an even
    count. Raises ``ValueError`` for no finite value."""
    ordered = sorted((float(v), int(s)) for s, v in values.items() if math.isfinite(float(v)))
    if not ordered:
        raise ValueError("no seed has a finite validation RMSE: nothing to choose from")
    return ordered[(len(ordered) - 1) // 2][1]


@dataclass(frozen=True)
class SeedStudy:
    """A finished study: ``runs`` in seed order and the ``chosen`` seed (:func:`median_seed`)."""

    estimator: str
    family: str
    scenario: str
    runs: tuple[SeedRun, ...]
    chosen: int

    @property
    def chosen_run(self) -> SeedRun:
        return next(r for r in self.runs if r.seed == self.chosen)

    def to_dict(self) -> dict[str, Any]:
        """The study as JSON data (``training.seed_study`` of the installed artefact)."""
        ok = [r.val_rmse for r in self.runs if r.status == "ok"]
        return {
            "estimator": self.estimator,
            "family": self.family,
            "scenario": self.scenario,
            "rule": SEED_RULE,
            "chosen_seed": self.chosen,
            "seeds": [r.seed for r in self.runs],
            "val_rmse_min": min(ok),
            "val_rmse_max": max(ok),
            "runs": [{k: v for k, v in asdict(r).items() if k != "out"} for r in self.runs],
        }

    def csv(self) -> str:
        """One line per seed: seed, status, val_rmse, test_rmse, best_epoch, epochs_run, seconds,
        chosen, error."""
        buffer = io.StringIO()
        fields = ["seed", "status", "val_rmse", "test_rmse", "best_epoch", "epochs_run", "seconds", "chosen", "error"]
        writer = csv.DictWriter(buffer, fields, lineterminator="\n")
        writer.writeheader()
        for run in self.runs:
            row = {k: getattr(run, k) for k in fields if k != "chosen"}
            writer.writerow({**row, "chosen": run.seed == self.chosen, "error": run.error or ""})
        return buffer.getvalue()


def _run_of(seed: int, outcome: Any) -> SeedRun:
    best = outcome.best()
    value = best.get("val_rmse", math.nan)
    if not math.isfinite(value):  # (an estimator that logs no RMSE: its validation loss)
        value = best.get("val_loss", math.nan)
    summary = outcome.summary()
    test = summary.get("test_rmse")
    return SeedRun(seed=seed, status="ok" if math.isfinite(value) else "failed", val_rmse=float(value),
                   best_epoch=int(outcome.best_epoch), epochs_run=int(summary["epochs_run"]),
                   seconds=round(float(summary["seconds"]), 1), test_rmse=None if test is None else float(test),
                   out=str(outcome.out), error=None if math.isfinite(value) else "non-finite validation RMSE")


def train_seeds(
    estimator: str,
    scenarios: Sequence[str | Scenario],
    options: Mapping[str, Any],
    seeds: Sequence[int],
    *,
    out: str | Path,
    family: str | None = None,
    resume: bool = False,
    progress: bool = True,
    log: Callable[[str], None] | None = None,
) -> SeedStudy:
    """Train ``estimator`` on ``scenarios`` with the config ``options`` once per seed of
    ``seeds`` (each overrides ``options``' seed) into ``out/seed-<K>/``, choose the median
    validation seed and write ``out/seed_study.json`` and ``.csv`` (module docstring).

    ``resume`` continues each seed from its own checkpoint where one is there (``fit(...,
    resume=True)``), so an interrupted study goes on where it stopped (a finished seed is evaluated
    again, not retrained; its seconds still count the epochs it ran before). A seed whose training
    raises ``ValueError`` or ``FloatingPointError`` is recorded as failed (a ``ValueError`` of the
    first seed is raised at once: a configuration the estimator refuses fails every seed alike). Raises ``ValueError``
    for fewer than one seed, repeated seeds or no seed that trained.
    """
    from fkn_bench.training import fit

    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("a seed study needs at least one seed")
    if len(set(seeds)) != len(seeds) or min(seeds) < 0:
        raise ValueError(f"training seeds must be distinct and >= 0 (got {seeds})")
    say = log or (lambda message: None)
    out = Path(out)
    runs: list[SeedRun] = []
    outcome = None
    for number, seed in enumerate(seeds, 1):
        directory = out / f"seed-{seed}"
        say(f"[seeds] seed {seed} ({number} of {len(seeds)}) -> {directory}")
        again = resume and (directory / "checkpoint.pt").is_file()
        try:
            outcome = fit(estimator, list(scenarios), {**options, "seed": seed}, out=directory, resume=again,
                          progress=progress, family=family)
        except FloatingPointError as exc:
            runs.append(SeedRun(seed=seed, status="failed", val_rmse=math.nan, out=str(directory), error=str(exc)))
            say(f"[seeds] seed {seed} failed: {exc}")
            continue
        except ValueError as exc:
            if not runs:  # the configuration itself: every seed would fail alike
                raise
            runs.append(SeedRun(seed=seed, status="failed", val_rmse=math.nan, out=str(directory), error=str(exc)))
            say(f"[seeds] seed {seed} failed: {exc}")
            continue
        runs.append(_run_of(seed, outcome))
        say(f"[seeds] seed {seed}: validation RMSE {runs[-1].val_rmse:.5g}, best epoch {runs[-1].best_epoch}, "
            f"{runs[-1].seconds:.0f} s")
    chosen = median_seed({r.seed: r.val_rmse for r in runs if r.status == "ok"})
    first = outcome.scenarios if outcome is not None and outcome.scenarios else ()
    label = "+".join(s.name for s in first) or "+".join(str(getattr(s, "name", s)) for s in scenarios)
    study = SeedStudy(estimator=estimator, family=(outcome.family if outcome is not None and outcome.family else
                                                   family or ""), scenario=label, runs=tuple(runs), chosen=chosen)
    write_json_atomic(out / SEED_STUDY_FILE, {**study.to_dict(), "runs": [asdict(r) for r in runs]})
    write_text_atomic(out / SEED_STUDY_FILE.replace(".json", ".csv"), study.csv())
    return study


def install_seed_study(study: SeedStudy) -> list[Path]:
    """Install ``study``'s chosen run as the committed artefact of its estimator and family
    (``training.seed_study`` added) and every other successful seed's run under the params
    folder's ``seeds/`` (:func:`~fkn_bench.training.artifacts.seed_artifact_path`), removing seed
    files of an earlier study that this one does not have; returns the files written."""
    from fkn_bench.training.artifacts import install_artifact, seed_artifact_path

    record = study.to_dict()
    written = [install_artifact(Path(study.chosen_run.out) / "parameters.json", study.estimator, study.family,
                                training_extra={"seed_study": record})]
    kept = set()
    for run in study.runs:
        if run.status != "ok" or run.seed == study.chosen:
            continue
        target = seed_artifact_path(study.estimator, study.family, run.seed)
        written.append(install_artifact(Path(run.out) / "parameters.json", study.estimator, study.family,
                                        target=target, training_extra={"seed_study": record}))
        kept.add(target.name)
    folder = seed_artifact_path(study.estimator, study.family, 0).parent
    prefix = f"{study.estimator}-{study.family}-seed"
    for stale in sorted(folder.glob(f"{prefix}*")) if folder.is_dir() else []:
        stem = stale.name.removesuffix(".weights.pt").removesuffix(".json") + ".json"
        if stem not in kept and stale.name[len(prefix):].split(".")[0].isdigit():
            stale.unlink()
    return written
