"""Another program's estimates, scored beside fkn-bench's estimators: :class:`ExternalEstimates`
returns an external estimate already put onto the truth's grid
(:class:`fkn_bench.envs.association.AssociatedEstimate`), whatever the measurements.

It runs nothing and learns nothing. ``recorded = True`` tells the harness that its costs (time per
step, memory) are not fkn-bench's to measure: they are left empty, and the cell's notes hold the
association report (:meth:`ExternalEstimates.report`). ``causal`` is what the producing program
was: a filter (onboard EKF, a visual-inertial odometry front end) is causal and is ranked with
fkn-bench's filters; a smoother's or a batch optimiser's output (every estimate uses the whole
run) is not, and belongs beside the ranking, as fkn-bench's own smoothers. fkn-bench cannot tell
from the output; the default is True (a topic published while the robot ran), and a caller who
knows otherwise builds it with ``causal=False``.

It is not in the estimator registry (it needs its data, not a scenario): the harness builds one
per ``--estimate-topic`` / ``--estimate`` (:func:`fkn_bench.harness.sources.external_estimators`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from fkn_bench.envs.association import AssociatedEstimate, ExternalSeries, align_se3, associate
from fkn_bench.estimators.base import Estimate, Estimates, Estimator, check_batch_inputs
from fkn_bench.types import ArrayB, ArrayF, Bool, Float

__all__ = ["ExternalEstimates"]


class ExternalEstimates(Estimator):
    """The estimates of ``associated`` (``T`` steps of the truth's grid) for every sequence.

    ``estimate(measurements, mask, dt)`` ignores the measurements (their shape must be
    ``(B, T, 7)``) and returns ``means`` ``(B, T, 13)`` (the same row for each sequence), and
    ``initialised``; no covariances (the metrics' NEES needs a 12x12 error covariance, an external
    pose covariance is 6x6; it is in ``extras["pose_covariances"]`` ``(B, T, 6, 6)`` when given) and
    no innovations. ``reset``/``step`` replay the same estimates one step at a time.

    Args:
        associated: the estimate on the grid.
        dt: the grid's step, s (``estimate`` refuses another).
        causal: whether the producing program was causal (module docstring).
    """

    description = "another program's estimates (a recording topic or a TUM/CSV file), replayed on the truth's grid"
    recorded = True
    """Costs are not measured (module docstring)."""

    def __init__(self, associated: AssociatedEstimate, dt: float, *, causal: bool = True) -> None:
        self.associated = associated
        self.name = associated.name
        self.dt = float(dt)
        self.causal = bool(causal)
        self._k = 0

    @classmethod
    def from_series(cls, series: ExternalSeries, grid_ns: np.ndarray, dt: float, *, tolerance_s: float | None = None,
                    truth: Float[ArrayF, "T 13"] | None = None, align: str | None = None,
                    causal: bool = True) -> ExternalEstimates:
        """Associate ``series`` with the grid ``grid_ns`` (``tolerance_s``: None for the default) and,
        with ``align="se3"``, align it to ``truth`` (:mod:`fkn_bench.envs.association`)."""
        if align not in (None, "none", "se3"):
            raise ValueError(f"align must be None, 'none' or 'se3' (got {align!r})")
        associated = associate(series, grid_ns, tolerance_s=tolerance_s)
        if align == "se3":
            if truth is None:
                raise ValueError("align='se3' needs the truth")
            associated = align_se3(associated, truth)
        return cls(associated, dt, causal=causal)

    @property
    def n_steps(self) -> int:
        return len(self.associated.states)

    def report(self) -> dict[str, Any]:
        """The association report (:meth:`AssociatedEstimate.report`)."""
        return self.associated.report()

    def estimate(self, measurements: Float[ArrayF, "B T 7"], mask: Bool[ArrayB, "B T"], dt: float) -> Estimates:
        measurements, mask, dt = check_batch_inputs(measurements, mask, dt)
        batch, steps = measurements.shape[:2]
        if steps != self.n_steps:
            raise ValueError(f"{self.name} holds {self.n_steps} steps of the truth's grid; the sequences have {steps}")
        if abs(dt - self.dt) > 1e-9 * self.dt:
            raise ValueError(f"{self.name} is on a grid of {self.dt:g} s steps, not {dt:g} s")
        a = self.associated
        extras = {}
        if a.covariances is not None:
            extras["pose_covariances"] = np.repeat(a.covariances[None], batch, axis=0)
        return Estimates(
            means=np.repeat(a.states[None], batch, axis=0),
            initialised=np.repeat(a.initialised[None], batch, axis=0),
            extras=extras,
        )

    def reset(self, *, dt: float) -> None:
        if abs(float(dt) - self.dt) > 1e-9 * self.dt:
            raise ValueError(f"{self.name} is on a grid of {self.dt:g} s steps, not {dt:g} s")
        self._k = 0

    def step(self, observation: Any) -> Estimate:
        """The estimate of the next grid step (``observation`` is ignored)."""
        k = self._k
        if k >= self.n_steps:
            raise ValueError(f"{self.name} holds {self.n_steps} steps; step {k} is beyond them")
        self._k += 1
        a = self.associated
        return Estimate(k * self.dt, a.states[k].copy(), None, bool(a.initialised[k]), bool(a.associated[k]))

    def to_config(self) -> dict[str, Any]:
        """What identifies the estimates (not the data: the ``digest`` changes with it)."""
        a = self.associated
        return {"name": self.name, "source": a.source, "tolerance_s": a.tolerance_s, "dt": self.dt,
                "aligned": a.alignment is not None, "causal": self.causal, "digest": a.digest}

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> Estimator:
        raise TypeError("external estimates are data, not a configuration: build them again from their source "
                        "(ExternalEstimates.from_series)")
