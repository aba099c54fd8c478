"""The noise of a state-space model: what its covariances are called, and their values.

* :class:`NoiseLayout` names the components of a model's process noise ``Q``, measurement noise
  ``R`` and initial covariance ``P0``, with units and default standard deviations (for the pose
  model the paper's manual tuning, FlexKalmanNet section 4.3).
* :class:`NoiseParameters` holds what a filter consumes: ``Q``, ``R`` and ``P0`` as covariance
  matrices (torch tensors). Leading axes: ``()`` shared by every sequence, ``(B,)`` one per
  sequence, or ``(B, T)`` one per step (time-varying, e.g. FlexKalmanNet's adaptive mode).

torch is imported when a :class:`NoiseParameters` is made, not with this module (the truth
simulator reads the models without it).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from torch import Tensor

__all__ = ["NoiseLayout", "NoiseParameters"]


@dataclass(frozen=True)
class NoiseLayout:
    """Component names, units and default standard deviations of a variant's ``Q``, ``R``, ``P0``."""

    q_labels: tuple[str, ...]
    q_units: tuple[str, ...]
    q_default: tuple[float, ...]
    r_labels: tuple[str, ...]
    r_units: tuple[str, ...]
    r_default: tuple[float, ...]
    p0_labels: tuple[str, ...]
    p0_units: tuple[str, ...]
    p0_default: tuple[float, ...]

    def labels(self, entry: str) -> tuple[str, ...]:
        return {"q": self.q_labels, "r": self.r_labels, "p0": self.p0_labels}[entry.split("_")[0]]

    def units(self, entry: str) -> tuple[str, ...]:
        return {"q": self.q_units, "r": self.r_units, "p0": self.p0_units}[entry.split("_")[0]]

    def default(self, entry: str) -> tuple[float, ...]:
        return {"q": self.q_default, "r": self.r_default, "p0": self.p0_default}[entry.split("_")[0]]

    def default_noise(self, dtype: Any = None) -> NoiseParameters:
        """The default standard deviations as diagonal covariances (float64 unless ``dtype``)."""
        return NoiseParameters.from_std(self.q_default, self.r_default, self.p0_default, dtype=dtype)


@dataclass(frozen=True)
class NoiseParameters:
    """Covariances consumed by a filter (see module docstring for the leading axes).

    Attributes:
        process: ``Q`` ``(..., nq, nq)``.
        measurement: ``R`` ``(..., m, m)``.
        initial: ``P0`` ``(..., n, n)`` used when a filter initialises from a measurement.
    """

    process: Tensor
    measurement: Tensor
    initial: Tensor

    @classmethod
    def from_std(
        cls,
        q_std: Tensor | Sequence[float],
        r_std: Tensor | Sequence[float],
        p0_std: Tensor | Sequence[float],
        *,
        dtype: Any = None,
    ) -> NoiseParameters:
        """Diagonal covariances from standard deviations (``(..., k)`` each; exactly symmetric),
        on the device of a tensor given (a sequence: torch's default device); ``dtype``
        default float64."""
        import torch

        dtype = torch.float64 if dtype is None else dtype

        def diag(std: Tensor | Sequence[float]) -> Tensor:
            t = std.to(dtype) if isinstance(std, torch.Tensor) else torch.as_tensor(std, dtype=dtype)
            return torch.diag_embed(t * t)

        return cls(diag(q_std), diag(r_std), diag(p0_std))

    def to(self, dtype: Any, device: Any = None) -> NoiseParameters:
        """The parameters in ``dtype`` (and on ``device``; None: where they are), differentiably."""
        return NoiseParameters(*(m.to(device=device, dtype=dtype) for m in (self.process, self.measurement, self.initial)))

    def at_step(self, t: int) -> NoiseParameters:
        """The parameters of step ``t`` when they are time-varying (``(B, T, k, k)``)."""
        pick = lambda m: m[:, t] if m.dim() == 4 else m  # noqa: E731
        return NoiseParameters(pick(self.process), pick(self.measurement), pick(self.initial))

    def steps(self) -> list[NoiseParameters]:
        """The parameters of every step, ``T`` of them (:meth:`at_step` for all ``t`` at once).

        One ``unbind`` per matrix: its backward stacks the steps' gradients once, where ``T``
        separate selections each allocate and fill a gradient of the whole ``(B, T, k, k)``
        tensor (quadratic in ``T``: 48% of a time-varying training epoch was that ``fill_``)."""
        steps = next(m.shape[1] for m in (self.process, self.measurement, self.initial) if m.dim() == 4)
        split = lambda m: m.unbind(1) if m.dim() == 4 else (m,) * steps  # noqa: E731
        return [NoiseParameters(*parts) for parts in zip(split(self.process), split(self.measurement), split(self.initial))]

    @property
    def time_varying(self) -> bool:
        return any(m.dim() == 4 for m in (self.process, self.measurement, self.initial))
