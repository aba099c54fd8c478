"""FlexKalmanNet as estimators of the common API.

* :class:`FlexKalmanNetEstimator` (``flexkalmannet``, the paper's use): the filter variant with the
  constant parameters the trained network yields on its training data. Runs from a learned-
  parameter artefact (this package's committed ``params/flexkalmannet-<family>.json`` by default,
  chosen by the scenario's ``model_family``) or from a checkpoint.
* :class:`AdaptiveFlexKalmanNetEstimator` (``flexkalmannet-tv``, or ``flexkalmannet`` with
  ``mode="time_varying"`` and a checkpoint): the network re-evaluated along the sequence, each
  step's parameters the mean of its outputs over the last ``history`` measurements. Runs from the
  committed weights ``params/flexkalmannet-tv-<family>.json`` (and ``.weights.pt``) of a
  network trained in that mode, or from a checkpoint.
"""

from __future__ import annotations

from collections import deque
from pathlib import Path
from typing import Any

import torch

from fkn_bench.estimators.base import Estimates, Estimator, RecursiveEstimator, check_batch_inputs, restart_diverged
from fkn_bench.estimators.kalman import MAX_STD, MIN_STD, filter_result_to_estimates
from fkn_bench.flexkalmannet.checkpoint import model_from_checkpoint
from fkn_bench.runtime import torch_threads
from fkn_bench.scenarios import Scenario
from fkn_bench.training.artifacts import (
    TrainedKalmanEstimator,
    artifact_factory,
    artifact_label,
    deployed_estimator_config,
    resolve_artifact_label,
    trained_network,
)
from fkn_bench.types import ArrayB, ArrayF

__all__ = ["FlexKalmanNetEstimator", "AdaptiveFlexKalmanNetEstimator", "flexkalmannet_factory", "flexkalmannet_tv_factory"]


class FlexKalmanNetEstimator(TrainedKalmanEstimator):
    """The filter with FlexKalmanNet's deployed constant parameters (see module docstring):
    a :class:`~fkn_bench.training.artifacts.TrainedKalmanEstimator` (keyword-only arguments of
    :class:`KalmanEstimator` plus ``metadata``), also built from a checkpoint."""

    default_name = "flexkalmannet"
    descriptions = {
        "flexkalmannet": "FlexKalmanNet: EKF with noise parameters learned by a network",
        "flexkalmannet-rigid-body": "FlexKalmanNet through the rigid-body model (inertia ratios estimated)",
    }

    @classmethod
    def from_checkpoint(cls, path: str | Path, *, gate: float | None = None) -> FlexKalmanNetEstimator:
        """The deployed constant parameters of a training checkpoint (``gate``: a chi-square
        innovation gate level, None: none)."""
        model, config, scenario, document = model_from_checkpoint(path)
        metadata = {"checkpoint": str(path), "scenario": scenario.name, "best_epoch": document.get("best_epoch")}
        gated = {} if gate is None else {"gate": gate}
        return cls(metadata=metadata, **deployed_estimator_config(model, config), **gated)


class AdaptiveFlexKalmanNetEstimator(RecursiveEstimator):
    """FlexKalmanNet's time-varying mode: per-step parameters from the recent measurements.

    Keyword-only arguments:
        checkpoint: a FlexKalmanNet training checkpoint (or committed weights file) holding the
            network; a committed file is named by its installation-independent label
            (:func:`~fkn_bench.training.artifacts.artifact_label`) in :meth:`to_config`.
        history: valid measurements averaged per step (default: the checkpoint's).
        gate: chi-square innovation gate level (None: none); see
            :meth:`~fkn_bench.filters.KalmanFilter.set_gate`.
        name, description: registry name and one-line description.
    """

    name = "flexkalmannet"
    description = "FlexKalmanNet, time-varying mode: the network's parameters averaged over recent measurements"

    def __init__(self, *, checkpoint: str | Path, history: int | None = None, gate: float | None = None,
                 name: str | None = None, description: str | None = None) -> None:
        self.checkpoint = artifact_label(resolve_artifact_label(checkpoint))
        self.model, self.config, self.scenario, document = model_from_checkpoint(resolve_artifact_label(checkpoint))
        # evaluated in float64 (float32 weights are exact in it): results then depend neither on
        # the batch size nor on the CPU's float32 kernels, so online and batch agree to rounding
        self.model.to(torch.float64)
        self.model.mode = "time_varying"
        recorded = document.get("scenario")  # what the harness reports as the training set
        names = [r.get("name") for r in (recorded if isinstance(recorded, list) else [recorded]) if isinstance(r, dict)]
        self.metadata: dict[str, Any] = {"scenario": {"name": "+".join(str(n) for n in names)}} if names else {}
        if history is not None:
            if history < 1:
                raise ValueError(f"history must be >= 1 (got {history})")
            self.model.history = int(history)
        self.filter = self.config.build_filter()
        self.filter.set_gate(gate)
        if name is not None:
            self.name = name
        if description is not None:
            self.description = description
        self._recent: deque[torch.Tensor] = deque(maxlen=self.model.history)

    def trusted(self, outputs: torch.Tensor) -> torch.Tensor:
        """``(N,)`` True where a measurement's network outputs ``(N, size)`` give finite noise
        whose variances lie in ``[MIN_STD^2, MAX_STD^2]`` (the range a constant-parameter
        :class:`~fkn_bench.estimators.KalmanEstimator` accepts). The rule: a measurement whose
        outputs fail (e.g. a usable but absurd pose far outside the training data, which the
        float32 network maps to an overflowing standard deviation) does not count in any step's
        mean, as if it were missing; the filter still uses it as a measurement."""
        if len(outputs) == 0:
            return torch.zeros(0, dtype=torch.bool)
        noise = self.model.parameter_set.to_noise(outputs)
        variances = torch.cat([torch.diagonal(m, dim1=-2, dim2=-1).reshape(len(outputs), -1)
                               for m in (noise.process, noise.measurement, noise.initial)], dim=-1)
        in_range = (variances >= MIN_STD**2) & (variances <= MAX_STD**2)  # (NaN fails)
        return torch.isfinite(outputs).all(-1) & in_range.all(-1)

    def estimate(self, measurements: ArrayF, mask: ArrayB, dt: float) -> Estimates:
        z, m, step = check_batch_inputs(measurements, mask, dt)
        with torch.no_grad(), torch_threads():
            zt, mt = torch.from_numpy(z), torch.from_numpy(m)
            usable_z, usable = self.filter.model.sanitize(zt, mt)  # what the filter would use (unit quaternions)
            noise = self.model.parameter_set.to_noise(self.model.sequence_raw(usable_z, usable, screen=self.trusted))
            result = self.filter.run(noise, zt, mt, dt=step)
        return restart_diverged(filter_result_to_estimates(result, self.filter), lambda zs, ms: self.estimate(zs, ms, step), z, m)

    def reset(self, *, dt: float) -> None:
        super().reset(dt=dt)
        self._recent.clear()

    def _online_observe(self, z: ArrayF | None) -> None:
        """The step's noise: the network's outputs averaged over the recent measurements, this
        step's included."""
        with torch.no_grad(), torch_threads():
            if z is not None:
                outputs = self.model._outputs(torch.from_numpy(z))
                if bool(self.trusted(outputs)[0]):
                    self._recent.append(outputs[0])
            raw = torch.stack(tuple(self._recent)).mean(0) if self._recent else self.model.deployed_raw()
            noise = self.model.parameter_set.to_noise(raw[None])
        self._online_noise = tuple(m[0].to(torch.float64).numpy() for m in (noise.process, noise.measurement, noise.initial))

    def to_config(self) -> dict[str, Any]:
        gate = {} if self.filter.gate is None else {"gate": self.filter.gate}
        return {"checkpoint": self.checkpoint, "history": self.model.history, **gate, "name": self.name,
                "description": self.description}


def flexkalmannet_factory(
    scenario: Scenario | None = None,
    *,
    checkpoint: str | Path | None = None,
    parameters: str | Path | None = None,
    mode: str = "constant",
    history: int | None = None,
    gate: float | None = None,
    training_seed: int | None = None,
) -> Estimator:
    """Registry factory of ``flexkalmannet``.

    Args:
        scenario: picks the committed artefact of the scenario's model family (see
            :func:`~fkn_bench.training.artifacts.artifact_family`).
        checkpoint: use this trained checkpoint instead of the committed parameters.
        parameters: use this learned-parameter JSON (e.g. written by ``fkn-bench train``).
        mode: ``constant`` (paper) or ``time_varying`` (needs ``checkpoint``; the committed
            time-varying network is ``flexkalmannet-tv``).
        history: time-varying mode: measurements averaged per step.
        gate: chi-square innovation gate level (None: none).
        training_seed: that seed of the committed artefact's seed study
            (:mod:`fkn_bench.training.seeds`) instead of the seed the study chose.
    """
    if sum(x is not None for x in (checkpoint, parameters, training_seed)) > 1:
        raise ValueError("give one of checkpoint=PATH, parameters=PATH and training_seed=K, not several")
    if mode == "time_varying":
        if checkpoint is None:
            raise ValueError("flexkalmannet mode 'time_varying' needs checkpoint=PATH (the network weights); "
                             "the committed time-varying FlexKalmanNet is the estimator flexkalmannet-tv")
        return AdaptiveFlexKalmanNetEstimator(checkpoint=checkpoint, history=history, gate=gate)
    if mode != "constant":
        raise ValueError(f"mode must be 'constant' or 'time_varying' (got {mode!r})")
    if checkpoint is not None:
        return FlexKalmanNetEstimator.from_checkpoint(checkpoint, gate=gate)
    return artifact_factory("flexkalmannet", FlexKalmanNetEstimator)(scenario, parameters=parameters, gate=gate,
                                                                      training_seed=training_seed)


def flexkalmannet_tv_factory(
    scenario: Scenario | None = None,
    *,
    checkpoint: str | Path | None = None,
    parameters: str | Path | None = None,
    history: int | None = None,
    gate: float | None = None,
    training_seed: int | None = None,
) -> AdaptiveFlexKalmanNetEstimator:
    """Registry factory of ``flexkalmannet-tv``: FlexKalmanNet trained and run in the time-varying
    mode, from ``checkpoint=PATH``, the ``parameters=PATH`` of a ``fkn-bench train --estimator
    flexkalmannet-tv`` run, or by default the committed weights of the scenario's model family
    (``fkn_bench/flexkalmannet/params/flexkalmannet-tv-<family>.json`` and ``.weights.pt``)."""
    weights = trained_network("flexkalmannet-tv", "time-varying FlexKalmanNet", scenario, checkpoint, parameters,
                              training_seed)
    return AdaptiveFlexKalmanNetEstimator(
        checkpoint=weights, history=history, gate=gate, name="flexkalmannet-tv",
        description="FlexKalmanNet, time-varying: per-step noise from the network's outputs on recent measurements",
    )
