"""KalmanNet as an estimator of the common API (``kalmannet`` in the registry).

Batch ``estimate`` runs :meth:`~fkn_bench.kalmannet.KalmanNet.run` on the whole batch; online
``reset``/``step`` is the project's one online recursion
(:class:`~fkn_bench.estimators.RecursiveEstimator`: time handling, initialisation at the first
usable measurement, skipped updates) with KalmanNet's pure step functions on a batch of one, the
GRUs' hidden states carried in the online state. Both paths run the same functions and agree to
rounding: 1e-10 with a float64 network (tested), ~2e-8 with a float32 one (its matrix products
round differently for a batch of one and of many). A network loaded from a checkpoint or from
committed weights is therefore evaluated in float64 (its float32 weights are exact there): results
that do not depend on the batch size or the CPU's float32 kernels; one passed as ``network=``
runs as it is.

KalmanNet carries no covariance: ``Estimates.covariances``, ``error_covariances`` and the
innovation covariances are None, as is ``Estimate.native_covariance`` online, so the harness
reports no NEES/NIS for it (NaN), while every error metric is scored as for the other estimators.

Recursive KalmanNet (``recursive-kalmannet``, :class:`RecursiveKalmanNetEstimator`) carries one:
the 12x12 covariance of the error ``[dtheta, dr, dw, dv]`` (``error_covariances``; online the
``native_covariance``, as the multiplicative EKF's), with the 13x13 state covariance derived from
it (``covariances``), so that the harness scores its NEES. It has no innovation covariance (it
learns no measurement noise), so no NIS (NaN).

Split-KalmanNet (``split-kalmannet``, :class:`SplitKalmanNetEstimator`) and Cholesky-KalmanNet
(``cholesky-kalmannet``, :class:`CholeskyKalmanNetEstimator`) report their error covariances the
same way (:mod:`fkn_bench.kalmannet.split` and :mod:`fkn_bench.kalmannet.cholesky` say what is
learned and what is derived), and no NIS.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from fkn_bench.estimators.base import Estimates, RecursiveEstimator, check_batch_inputs, restart_diverged
from fkn_bench.filters.recursion import Proposal
from fkn_bench.filters.pose import error_covariance_from_state, state_covariance_from_error, with_unit_quaternion
from fkn_bench.kalmannet.checkpoint import (cholesky_model_from_checkpoint, model_from_checkpoint,
                                            recursive_model_from_checkpoint, split_model_from_checkpoint)
from fkn_bench.kalmannet.cholesky import CholeskyKalmanNet
from fkn_bench.kalmannet.recursion import KalmanNet, KalmanNetState, NetworkSteps
from fkn_bench.kalmannet.recursive import RecursiveKalmanNet
from fkn_bench.kalmannet.split import SplitKalmanNet
from fkn_bench.linalg import symmetrize
from fkn_bench.runtime import torch_threads
from fkn_bench.scenarios import Scenario
from fkn_bench.training.artifacts import artifact_label, resolve_artifact_label, trained_network
from fkn_bench.types import ArrayB, ArrayF

__all__ = ["KalmanNetEstimator", "kalmannet_factory", "RecursiveKalmanNetEstimator", "recursive_kalmannet_factory",
           "SplitKalmanNetEstimator", "split_kalmannet_factory", "CholeskyKalmanNetEstimator", "cholesky_kalmannet_factory"]

_ONE = np.ones(1, dtype=bool)


class _OnlineSteps(NetworkSteps):
    """:class:`~fkn_bench.kalmannet.recursion.NetworkSteps` for the online step (batch 1):
    numpy measurements in, torch states, no gradients."""

    def predict(self, state: Any, t: int, dt: float) -> Any:
        with torch.no_grad():
            return super().predict(state, t, dt)

    def initial(self, state: Any, z: ArrayF, t: int) -> Any:
        with torch.no_grad():
            return super().initial(state, torch.from_numpy(z), t)

    def propose(self, state: Any, z: ArrayF, rows: ArrayB, t: int) -> Proposal:
        with torch.no_grad(), torch_threads():
            proposal = super().propose(state, torch.from_numpy(z), rows, t)
        if proposal.innovation is None:
            return proposal
        return Proposal(proposal.state, proposal.innovation.numpy(), proposal.innovation_covariance.numpy())


class KalmanNetEstimator(RecursiveEstimator):
    """A trained KalmanNet (see module docstring).

    Keyword-only arguments:
        checkpoint: a training checkpoint of ``kalmannet`` (``fkn-bench train --estimator
            kalmannet`` writes ``OUT/checkpoint.pt``).
        network: a :class:`KalmanNet` module instead (e.g. fresh from training; not saved by
            :meth:`to_config`).
        name, description: registry name and one-line description.
    """

    def __init__(
        self,
        *,
        checkpoint: str | Path | None = None,
        network: KalmanNet | None = None,
        name: str = "kalmannet",
        description: str = "KalmanNet (architecture 2): a recurrent network computes the Kalman gain",
    ) -> None:
        if (checkpoint is None) == (network is None):
            raise ValueError(f"give either checkpoint=PATH or network={type(self).__name__.removesuffix('Estimator')}(...)")
        # a committed file is named by its label (fkn_bench.kalmannet/params/...), not by where this
        # checkout is, so that configurations and their fingerprints do not depend on it
        self.checkpoint = None if checkpoint is None else artifact_label(resolve_artifact_label(checkpoint))
        self.metadata: dict[str, Any] = {}
        if network is None:
            self.net, _, _, document = self._load(resolve_artifact_label(checkpoint))  # type: ignore[arg-type]
            # evaluated in float64: float32 weights are exact in it, and the results then do not
            # depend on the batch size or on the CPU's float32 kernels (a batch of 2 and of 20
            # differed by 1e-6 relative in float32), so the accuracy gate can hold them to rounding
            self.net.to(torch.float64)
            recorded = document.get("scenario")  # a dict, or a list of them for a mixture
            names = [s.get("name") for s in (recorded if isinstance(recorded, list) else [recorded]) if isinstance(s, dict)]
            if names:  # what the harness reports as the training set ("trained on ...")
                self.metadata["scenario"] = {"name": "+".join(str(n) for n in names)}
        else:
            self.net = network
        self.net.eval()
        if self.net.manifold.measurement_dim != 7 or self.net.manifold.state_dim != 13:
            raise ValueError("the estimator API needs the pose model (13 states, 7 measurements)")
        self.name, self.description = name, description

    @staticmethod
    def _load(checkpoint: str | Path) -> tuple[Any, Any, Any, dict[str, Any]]:
        return model_from_checkpoint(checkpoint)

    # ------------------------------------------------------------------ batch
    def estimate(self, measurements: ArrayF, mask: ArrayB, dt: float) -> Estimates:
        z, m, step = check_batch_inputs(measurements, mask, dt)
        with torch.no_grad(), torch_threads():
            run = self.net.run(torch.from_numpy(z), torch.from_numpy(m), dt=step)
        means = with_unit_quaternion(run.means.numpy())
        covariances = error_covariances = None
        if run.covariances is not None:
            native = symmetrize(run.covariances.numpy())
            if native.shape[-1] == 12:  # the error covariance (pose tangent space)
                error_covariances, covariances = native, state_covariance_from_error(means[..., :4], native)
            else:  # a 13x13 state covariance (the Euclidean manifold forced on the pose model)
                covariances, error_covariances = native, error_covariance_from_state(means[..., :4], native)
        estimates = Estimates(
            means=means,
            covariances=covariances,
            error_covariances=error_covariances,
            innovation_mask=run.updated.numpy(),
            initialised=run.initialised.numpy(),
        )
        return restart_diverged(estimates, lambda zs, ms: self.estimate(zs, ms, step), z, m)

    # ------------------------------------------------------------------ online (batch of one)
    def _online_sanitize(self, z: ArrayF) -> ArrayF | None:
        out, usable = self.net.model.sanitize(z, _ONE)
        return out if usable[0] else None

    def _online_prior(self) -> KalmanNetState:
        return self.net.prior(1, torch.float64)

    def _online_steps(self) -> _OnlineSteps:
        return _OnlineSteps(self.net)

    def _online_report(self, state: KalmanNetState) -> tuple[ArrayF, ArrayF | None]:
        covariance = getattr(state, "covariance", None)
        return state.mean[0].numpy(), None if covariance is None else symmetrize(covariance[0].numpy())

    # ------------------------------------------------------------------ config
    def to_config(self) -> dict[str, Any]:
        if self.checkpoint is None:
            raise ValueError(f"a {type(self).__name__} built from a module has no config; build it from a checkpoint")
        return {"checkpoint": self.checkpoint, "name": self.name, "description": self.description}


def kalmannet_factory(
    scenario: Scenario | None = None,
    *,
    checkpoint: str | Path | None = None,
    parameters: str | Path | None = None,
    training_seed: int | None = None,
) -> KalmanNetEstimator:
    """Registry factory of ``kalmannet``: a trained network from ``checkpoint=PATH``, from the
    ``parameters=PATH`` (``parameters.json``) of a ``fkn-bench train --estimator kalmannet`` run,
    or by default the committed weights of the scenario's model family
    (``fkn_bench/kalmannet/params/kalmannet-<family>.json`` and ``.weights.pt``), or with
    ``training_seed=K`` that seed of the committed artefact's seed study
    (:mod:`fkn_bench.training.seeds`)."""
    return KalmanNetEstimator(
        checkpoint=trained_network("kalmannet", "KalmanNet", scenario, checkpoint, parameters, training_seed)
    )


class RecursiveKalmanNetEstimator(KalmanNetEstimator):
    """A trained Recursive KalmanNet (module docstring; Mortada et al., EUSIPCO 2025): estimates
    with their error covariance.

    Keyword-only arguments:
        checkpoint: a training checkpoint of ``recursive-kalmannet`` (``fkn-bench train
            --estimator recursive-kalmannet`` writes ``OUT/checkpoint.pt``).
        network: a :class:`RecursiveKalmanNet` module instead.
        name, description: registry name and one-line description.
    """

    net: RecursiveKalmanNet

    def __init__(
        self,
        *,
        checkpoint: str | Path | None = None,
        network: RecursiveKalmanNet | None = None,
        name: str = "recursive-kalmannet",
        description: str = "Recursive KalmanNet: recurrent networks compute the gain and the error covariance",
    ) -> None:
        super().__init__(checkpoint=checkpoint, network=network, name=name, description=description)  # type: ignore[arg-type]

    @staticmethod
    def _load(checkpoint: str | Path) -> tuple[Any, Any, Any, dict[str, Any]]:
        return recursive_model_from_checkpoint(checkpoint)


def recursive_kalmannet_factory(
    scenario: Scenario | None = None,
    *,
    checkpoint: str | Path | None = None,
    parameters: str | Path | None = None,
    training_seed: int | None = None,
) -> RecursiveKalmanNetEstimator:
    """Registry factory of ``recursive-kalmannet``, as :func:`kalmannet_factory`."""
    return RecursiveKalmanNetEstimator(
        checkpoint=trained_network("recursive-kalmannet", "Recursive KalmanNet", scenario, checkpoint, parameters, training_seed)
    )


class SplitKalmanNetEstimator(KalmanNetEstimator):
    """A trained Split-KalmanNet (Choi et al., IEEE TVT 2023; :mod:`fkn_bench.kalmannet.split`):
    estimates with their error covariance.

    Keyword-only arguments:
        checkpoint: a training checkpoint of ``split-kalmannet`` (``fkn-bench train --estimator
            split-kalmannet`` writes ``OUT/checkpoint.pt``).
        network: a :class:`SplitKalmanNet` module instead.
        name, description: registry name and one-line description.
    """

    net: SplitKalmanNet

    def __init__(
        self,
        *,
        checkpoint: str | Path | None = None,
        network: SplitKalmanNet | None = None,
        name: str = "split-kalmannet",
        description: str = "Split-KalmanNet: recurrent networks compute the prior and innovation covariances of the gain",
    ) -> None:
        super().__init__(checkpoint=checkpoint, network=network, name=name, description=description)  # type: ignore[arg-type]

    @staticmethod
    def _load(checkpoint: str | Path) -> tuple[Any, Any, Any, dict[str, Any]]:
        return split_model_from_checkpoint(checkpoint)


def split_kalmannet_factory(
    scenario: Scenario | None = None,
    *,
    checkpoint: str | Path | None = None,
    parameters: str | Path | None = None,
    training_seed: int | None = None,
) -> SplitKalmanNetEstimator:
    """Registry factory of ``split-kalmannet``, as :func:`kalmannet_factory`."""
    return SplitKalmanNetEstimator(
        checkpoint=trained_network("split-kalmannet", "Split-KalmanNet", scenario, checkpoint, parameters, training_seed)
    )


class CholeskyKalmanNetEstimator(SplitKalmanNetEstimator):
    """A trained Cholesky-KalmanNet (Ko & Shafieezadeh, IEEE SPL 2025;
    :mod:`fkn_bench.kalmannet.cholesky`): estimates with their error covariance; arguments as
    :class:`SplitKalmanNetEstimator`'s (a ``cholesky-kalmannet`` checkpoint, or a
    :class:`CholeskyKalmanNet` module)."""

    net: CholeskyKalmanNet

    def __init__(
        self,
        *,
        checkpoint: str | Path | None = None,
        network: CholeskyKalmanNet | None = None,
        name: str = "cholesky-kalmannet",
        description: str = "Cholesky-KalmanNet: recurrent networks compute Cholesky factors of the gain's covariances",
    ) -> None:
        super().__init__(checkpoint=checkpoint, network=network, name=name, description=description)

    @staticmethod
    def _load(checkpoint: str | Path) -> tuple[Any, Any, Any, dict[str, Any]]:
        return cholesky_model_from_checkpoint(checkpoint)


def cholesky_kalmannet_factory(
    scenario: Scenario | None = None,
    *,
    checkpoint: str | Path | None = None,
    parameters: str | Path | None = None,
    training_seed: int | None = None,
) -> CholeskyKalmanNetEstimator:
    """Registry factory of ``cholesky-kalmannet``, as :func:`kalmannet_factory`."""
    return CholeskyKalmanNetEstimator(
        checkpoint=trained_network("cholesky-kalmannet", "Cholesky-KalmanNet", scenario, checkpoint, parameters, training_seed)
    )
