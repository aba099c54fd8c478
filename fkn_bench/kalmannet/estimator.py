"""KalmanNet as an estimator of the common API (``kalmannet`` in the registry).

Batch ``estimate`` runs :meth:`~fkn_bench.kalmannet.KalmanNet.run` on the whole batch; online
``reset``/``step`` is the project's one online recursion
(:class:`~fkn_bench.estimators.RecursiveEstimator`: time handling, initialisation at the first
usable measurement, skipped updates) with KalmanNet's pure step functions on a batch of one, the
GRUs' hidden states carried in the online state. Both paths run the same functions and agree to
rounding: 1e-10 with a float64 network (tested), ~2e-8 with the default float32 network (its
matrix products round differently for a batch of one and of many).

KalmanNet carries no covariance: ``Estimates.covariances``, ``error_covariances`` and the
innovation covariances are None, as is ``Estimate.native_covariance`` online, so the harness
reports no NEES/NIS for it (NaN), while every error metric is scored as for the other estimators.

Recursive KalmanNet (``recursive-kalmannet``, :class:`RecursiveKalmanNetEstimator`) carries one:
the 12x12 covariance of the error ``[dtheta, dr, dw, dv]`` (``error_covariances``; online the
``native_covariance``, as the multiplicative EKF's), with the 13x13 state covariance derived from
it (``covariances``), so that the harness scores its NEES. It has no innovation covariance (it
learns no measurement noise), so no NIS (NaN).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from fkn_bench.estimators.base import Estimates, RecursiveEstimator, check_batch_inputs
from fkn_bench.filters.pose import error_covariance_from_state, state_covariance_from_error, with_unit_quaternion
from fkn_bench.kalmannet.checkpoint import model_from_checkpoint, recursive_model_from_checkpoint
from fkn_bench.kalmannet.recursion import KalmanNet, KalmanNetState
from fkn_bench.kalmannet.recursive import RecursiveKalmanNet, RecursiveKalmanNetState
from fkn_bench.linalg import symmetrize
from fkn_bench.runtime import torch_threads
from fkn_bench.scenarios import Scenario
from fkn_bench.training.artifacts import ArtifactError, read_artifact
from fkn_bench.types import ArrayB, ArrayF

__all__ = ["KalmanNetEstimator", "kalmannet_factory", "RecursiveKalmanNetEstimator", "recursive_kalmannet_factory"]

_ONE = np.ones(1, dtype=bool)


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
            raise ValueError("give either checkpoint=PATH or network=KalmanNet(...)")
        self.checkpoint = None if checkpoint is None else str(checkpoint)
        self.net = network if network is not None else self._load(checkpoint)  # type: ignore[arg-type]
        self.net.eval()
        if self.net.manifold.measurement_dim != 7 or self.net.manifold.state_dim != 13:
            raise ValueError("the estimator API needs the pose model (13 states, 7 measurements)")
        self.name, self.description = name, description

    @staticmethod
    def _load(checkpoint: str | Path) -> Any:
        return model_from_checkpoint(checkpoint)[0]

    # ------------------------------------------------------------------ batch
    def estimate(self, measurements: ArrayF, mask: ArrayB, dt: float) -> Estimates:
        z, m, step = check_batch_inputs(measurements, mask, dt)
        with torch.no_grad(), torch_threads():
            run = self.net.run(torch.from_numpy(z), torch.from_numpy(m), dt=step)
        return Estimates(
            means=with_unit_quaternion(run.means.numpy()),
            innovation_mask=run.updated.numpy(),
            initialised=run.initialised.numpy(),
        )

    # ------------------------------------------------------------------ online (batch of one)
    def _online_sanitize(self, z: ArrayF) -> ArrayF | None:
        out, usable = self.net.model.sanitize(z, _ONE)
        return out if usable[0] else None

    def _online_prior(self) -> KalmanNetState:
        return self.net.prior(1, torch.float64)

    def _online_predict(self, state: KalmanNetState, dt: float) -> KalmanNetState:
        with torch.no_grad():
            return self.net.predict(state, dt)

    def _online_initial(self, state: KalmanNetState, z: ArrayF) -> KalmanNetState:
        with torch.no_grad():
            return self.net.initial(state, torch.from_numpy(z))

    def _online_update(self, state: KalmanNetState, z: ArrayF) -> KalmanNetState:
        with torch.no_grad(), torch_threads():
            return self.net.update(state, torch.from_numpy(z))

    def _online_report(self, state: KalmanNetState) -> tuple[ArrayF, None]:
        return state.mean[0].numpy(), None

    # ------------------------------------------------------------------ config
    def to_config(self) -> dict[str, Any]:
        if self.checkpoint is None:
            raise ValueError(f"a {type(self).__name__} built from a module has no config; build it from a checkpoint")
        return {"checkpoint": self.checkpoint, "name": self.name, "description": self.description}


def _checkpoint_of_artifact(path: str | Path, estimator: str = "kalmannet") -> Path:
    """The checkpoint a ``parameters.json`` of a KalmanNet (or ``estimator``) training names (as
    written, or beside the artefact when it was moved with it)."""
    document = read_artifact(path)
    if document["estimator"] != estimator:
        raise ArtifactError(f"{path} holds {document['estimator']!r} parameters, not {estimator}'s")
    named = document["estimator_config"].get("checkpoint")
    if named is not None and Path(named).is_file():
        return Path(named)
    beside = Path(path).parent / "checkpoint.pt"
    if beside.is_file():
        return beside
    raise ArtifactError(f"{path}: the KalmanNet checkpoint it names ({named}) is not there, nor {beside}")


def kalmannet_factory(
    scenario: Scenario | None = None,
    *,
    checkpoint: str | Path | None = None,
    parameters: str | Path | None = None,
) -> KalmanNetEstimator:
    """Registry factory of ``kalmannet``: a trained network from ``checkpoint=PATH`` or from the
    ``parameters=PATH`` (``parameters.json``) of a ``fkn-bench train --estimator kalmannet`` run.
    No trained weights are committed yet, so without either it raises (the harness then lists
    ``kalmannet`` as unavailable)."""
    if checkpoint is not None and parameters is not None:
        raise ValueError("give either checkpoint= or parameters=, not both")
    if parameters is not None:
        checkpoint = _checkpoint_of_artifact(parameters)
    if checkpoint is None:
        family = scenario.model_family if scenario is not None else "ds1"
        raise ArtifactError(
            f"no trained KalmanNet for model family '{family}': train one with `fkn-bench train --estimator kalmannet "
            f"--scenario {family} --out runs/kalmannet-{family}` and pass checkpoint=runs/kalmannet-{family}/checkpoint.pt"
        )
    return KalmanNetEstimator(checkpoint=checkpoint)


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
        if (checkpoint is None) == (network is None):
            raise ValueError("give either checkpoint=PATH or network=RecursiveKalmanNet(...)")
        super().__init__(checkpoint=checkpoint, network=network, name=name, description=description)  # type: ignore[arg-type]

    @staticmethod
    def _load(checkpoint: str | Path) -> Any:
        return recursive_model_from_checkpoint(checkpoint)[0]

    def estimate(self, measurements: ArrayF, mask: ArrayB, dt: float) -> Estimates:
        z, m, step = check_batch_inputs(measurements, mask, dt)
        with torch.no_grad(), torch_threads():
            run = self.net.run(torch.from_numpy(z), torch.from_numpy(m), dt=step)
        means = with_unit_quaternion(run.means.numpy())
        native = symmetrize(run.covariances.numpy())
        if native.shape[-1] == 12:  # the error covariance (pose tangent space)
            error_covariances, covariances = native, state_covariance_from_error(means[..., :4], native)
        else:  # a 13x13 state covariance (the Euclidean manifold forced on the pose model)
            covariances, error_covariances = native, error_covariance_from_state(means[..., :4], native)
        return Estimates(
            means=means,
            covariances=covariances,
            error_covariances=error_covariances,
            innovation_mask=run.updated.numpy(),
            initialised=run.initialised.numpy(),
        )

    def _online_prior(self) -> RecursiveKalmanNetState:
        return self.net.prior(1, torch.float64)

    def _online_report(self, state: RecursiveKalmanNetState) -> tuple[ArrayF, ArrayF]:  # type: ignore[override]
        return state.mean[0].numpy(), symmetrize(state.covariance[0].numpy())


def recursive_kalmannet_factory(
    scenario: Scenario | None = None,
    *,
    checkpoint: str | Path | None = None,
    parameters: str | Path | None = None,
) -> RecursiveKalmanNetEstimator:
    """Registry factory of ``recursive-kalmannet``: a trained network from ``checkpoint=PATH``
    or from the ``parameters=PATH`` (``parameters.json``) of a ``fkn-bench train --estimator
    recursive-kalmannet`` run. No trained weights are committed yet, so without either it raises
    (the harness then lists ``recursive-kalmannet`` as unavailable)."""
    if checkpoint is not None and parameters is not None:
        raise ValueError("give either checkpoint= or parameters=, not both")
    if parameters is not None:
        checkpoint = _checkpoint_of_artifact(parameters, "recursive-kalmannet")
    if checkpoint is None:
        family = scenario.model_family if scenario is not None else "ds1"
        raise ArtifactError(
            f"no trained Recursive KalmanNet for model family '{family}': train one with `fkn-bench train --estimator "
            f"recursive-kalmannet --scenario {family} --out runs/rkn-{family}` and pass "
            f"checkpoint=runs/rkn-{family}/checkpoint.pt"
        )
    return RecursiveKalmanNetEstimator(checkpoint=checkpoint)
