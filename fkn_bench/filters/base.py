"""The common interface of the filter variants and the recursion they share.

Every variant (EKF, UKF, multiplicative EKF) is a :class:`KalmanFilter`: it supplies
``predict`` and ``update`` for one step of a batch, and :meth:`KalmanFilter.run` runs the
recursion over a whole batch of sequences. The same call runs, and trains, any variant:

    result = variant.run(noise, measurements, mask, dt=0.1)   # (B, T, 7), (B, T) -> (B, T, 13)

Conventions of :meth:`KalmanFilter.run` (the project's one recursion,
:func:`fkn_bench.filters.recursion.scan`, on this filter's step functions):

* Step ``t`` predicts from ``t - 1`` (not at ``t = 0``) and then updates with measurement ``t``
  when ``mask[:, t]`` is true; a step without a measurement is predict-only.
* Without an explicit ``initial`` state, each sequence initialises at its first usable
  measurement (state from the model's ``initial_state``, covariance ``noise.initial``) and that
  measurement is not used again in an update; before it, the sequence reports the model's prior
  state propagated by the model.
* A stretch of steps where no row has a measurement (nine in ten on ds1) is predicted, with the
  prediction of the step after it, by one :meth:`KalmanFilter.predict_steps` call: the same
  states as one ``predict`` per step (the EKF does it in one call of its compiled kernels and
  one autograd node, where step by step the per-step overhead was most of a training epoch).
* Inputs are cleaned once by the model's ``sanitize`` (non-finite or unusable measurements are
  dropped from the mask: the documented rule is "skip the update"), so no NaN reaches the
  arithmetic, neither forward nor backward.
* Covariances are exactly symmetric: every variant's ``predict`` and ``update`` return their
  covariance symmetrised (``(P + P^T) / 2``, :func:`fkn_bench.linalg.symmetrize`), once each per
  step, or symmetric by construction (the structured EKF predict,
  :mod:`fkn_bench.filters.structured`), so ``run`` adds no symmetrisation of its own. Their
  strides are the variant's (the structured EKF's are views of ``(k, k, B)`` storage).

Everything is a differentiable torch operation; gradients flow into every tensor of ``noise``
(and ``initial``). float64 by default: the dtype of ``measurements`` decides.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import Tensor

from fkn_bench.models.base import StateSpaceModel
from fkn_bench.models.noise import NoiseLayout, NoiseParameters
from fkn_bench.filters.recursion import GATE_REINITIALISE_AFTER, Proposal, accept, count_rejections, gate_threshold, scan, start_carry
from fkn_bench.linalg import namespace, symmetrize
from fkn_bench.types import Bool, Float

__all__ = ["KalmanFilter", "FilterResult", "FilterState", "FilterSteps", "accept", "check_dt", "gate_threshold", "GATE_REINITIALISE_AFTER",
           "count_rejections"]


class FilterState(NamedTuple):
    """A batch of Gaussian filter states at one time.

    Attributes:
        mean: ``(B, n)`` state means.
        covariance: ``(B, k, k)`` covariances (``k = n`` for additive filters, the error-state
            dimension for the multiplicative EKF).
    """

    mean: Float[Tensor, "B n"]
    covariance: Float[Tensor, "B k k"]


@dataclass(frozen=True)
class FilterResult:
    """Output of :meth:`KalmanFilter.run` (batch first).

    Attributes:
        means: ``(B, T, n)`` posterior means.
        covariances: ``(B, T, k, k)`` posterior covariances, or None when not stored.
        innovations: ``(B, T, m)`` innovations ``z - h(x-)`` (zero where no update).
        innovation_covariances: ``(B, T, m, m)`` their covariances ``S`` (identity where no update).
        prior_means: ``(B, T, n)`` predicted means ``x-`` (stored with the innovations).
        updated: ``(B, T)`` True where a measurement update happened.
        initialised: ``(B, T)`` True from each sequence's initialisation on.
        final: the state after the last step (to continue filtering).
    """

    means: Float[Tensor, "B T n"]
    covariances: Float[Tensor, "B T k k"] | None
    innovations: Float[Tensor, "B T m"] | None
    innovation_covariances: Float[Tensor, "B T m m"] | None
    prior_means: Float[Tensor, "B T n"] | None
    updated: Bool[Tensor, "B T"]
    initialised: Bool[Tensor, "B T"]
    final: FilterState


def check_dt(dt: Any) -> float:
    """The time step ``dt`` (s) as a float; ``ValueError`` unless it is a finite number > 0 (a
    bool or a string is no number: ``True`` is not 1 s, ``"0.1"`` not 0.1 s)."""
    if isinstance(dt, (bool, str, bytes)):
        raise ValueError(f"dt must be a number (got {dt!r})")
    try:
        step = float(dt)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"dt must be a number (got {dt!r})") from None
    if not math.isfinite(step) or step <= 0:
        raise ValueError(f"dt must be a finite number > 0 (got {dt!r})")
    return step


def _check_noise_shapes(noise: NoiseParameters, batch: int, steps: int, k: int, m: int) -> None:
    """``Q``, ``P0`` must be ``(..., k, k)`` and ``R`` ``(..., m, m)`` with leading axes ``()``,
    ``(B,)`` or ``(B, T)`` (a leading 1 broadcasts over the batch)."""
    for name, matrix, dim in (("process", noise.process, k), ("measurement", noise.measurement, m), ("initial", noise.initial, k)):
        shape = tuple(matrix.shape)
        lead = shape[:-2]
        ok = (
            len(shape) >= 2
            and shape[-2:] == (dim, dim)
            and len(lead) <= 2
            and (not lead or lead[0] in (1, batch))
            and (len(lead) < 2 or lead[1] == steps)
        )
        if not ok:
            raise ValueError(
                f"noise.{name} must have shape ({dim}, {dim}), (B, {dim}, {dim}) or (B, T, {dim}, {dim}) "
                f"with B = {batch}, T = {steps} (got {shape})"
            )


def _empty(shape: tuple[int, ...], dtype: torch.dtype, device: torch.device) -> Tensor:
    """``torch.empty``, but on the CPU in memory numpy allocates: numpy advises the kernel to back
    allocations of 4 MB and more with transparent huge pages (``madvise``, Linux), so filling a
    fresh series faults once per 2 MB page rather than once per 4 kB page (``fkn_bench/DESIGN.md``,
    "Performance notes")."""
    if device.type != "cpu":
        return torch.empty(shape, dtype=dtype, device=device)
    try:
        numpy_dtype = torch.empty(0, dtype=dtype, device="cpu").numpy().dtype
    except TypeError:  # (a dtype numpy does not have)
        return torch.empty(shape, dtype=dtype)
    return torch.from_numpy(np.empty(shape, dtype=numpy_dtype))


class _StepOutputs:
    """One per-step output series, returned time-major ``(T, ...)``, in the memory layout of the
    steps' values.

    Without autograd the steps are written into one preallocated buffer: a list of per-step
    tensors kept alive would fragment the heap and make every step's temporaries fresh memory
    (page faults dominated large batches). With autograd the steps are collected and concatenated
    once: writing slices of one buffer would make the backward pass copy the whole buffer's
    gradient at every step (quadratic in T). Either way a series of matrices is laid out as the
    second step's value is (the structured EKF step returns batch-last views, ``(B, 13, 13)`` over
    ``(13, 13, B)`` storage), so storing a step is a straight copy, not a transposing one
    (which cost more than the step itself at B = 1024); the shape returned is the same.
    """

    def __init__(self, steps: int, shape: tuple[int, ...], dtype: torch.dtype, tracked: bool) -> None:
        self._steps, self._shape, self._dtype, self._tracked = steps, shape, dtype, tracked
        self._blocks: list[tuple[int, Tensor]] = []  # (first step, (count, ...) values), until allocated
        self._buffer: Tensor | None = None

    @staticmethod
    def _order(value: Tensor) -> list[int]:
        """``value``'s axes, outermost in memory first, for a per-step matrix (a covariance);
        the axes in order for a vector (a mean or an innovation: small, and read downstream
        along the state axis, which a batch-last layout would make a strided read)."""
        if value.dim() < 3:
            return list(range(value.dim()))
        return sorted(range(value.dim()), key=lambda axis: -value.stride(axis))

    @staticmethod
    def _restore(order: Sequence[int]) -> list[int]:
        """The permutation of a time-major series laid out ``(T, *order)`` back to ``(T, ...)``."""
        return [0, *(1 + list(order).index(axis) for axis in range(len(order)))]

    def _allocate(self, like: Tensor) -> None:
        order = self._order(like)
        storage = _empty((self._steps, *(self._shape[a] for a in order)), self._dtype, like.device)
        self._buffer = storage.permute(self._restore(order))
        for t, block in self._blocks:
            self._buffer[t : t + block.shape[0]] = block
        self._blocks = []

    def put(self, t: int, value: Tensor) -> None:
        """Step ``t``'s value."""
        self.put_steps(t, value.unsqueeze(0))

    def put_steps(self, t: int, values: Tensor) -> None:
        """The values ``(count, ...)`` of steps ``t`` to ``t + count - 1``."""
        # the layout is the second step's (the first is an initialisation's, laid out its own way)
        if not self._tracked and self._buffer is None and t + values.shape[0] > 1:
            self._allocate(values[-1])
        if self._buffer is None:  # (a copy without autograd, as the buffer's would be)
            self._blocks.append((t, values if self._tracked else values.clone()))
        else:
            self._buffer[t : t + values.shape[0]] = values

    def result(self) -> Tensor:
        if not self._tracked and self._buffer is None and self._blocks:
            self._allocate(self._blocks[-1][1][-1])
        if self._buffer is not None:
            return self._buffer
        order = self._order(self._blocks[-1][1][-1])
        time_major = [0, *(1 + axis for axis in order)]
        joined = torch.cat([block.permute(time_major) for _, block in self._blocks])
        return joined.permute(self._restore(order))


class FilterSteps:
    """A :class:`KalmanFilter`'s step functions for the one recursion
    (:mod:`fkn_bench.filters.recursion`), written once for the batch run and the online step:
    the filter's ``predict``, ``initial_state`` and ``update`` with the step's ``Q``, ``P0`` and
    ``R`` (:meth:`noise`, which a subclass gives); its chi-square gate; records nothing."""

    def __init__(self, filt: KalmanFilter) -> None:
        self.filter = filt
        self.nis_threshold = filt._gate_threshold if filt.gate is not None else math.inf

    def noise(self, t: int) -> tuple[Any, Any, Any]:
        """``(Q, R, P0)`` of step ``t``."""
        raise NotImplementedError

    def predict(self, state: FilterState, t: int, dt: float) -> FilterState:
        return self.filter.predict(state, self.noise(t)[0], dt)

    def initial(self, state: FilterState, z: Tensor, t: int) -> FilterState:
        return self.filter.initial_state(z, self.noise(t)[2])

    def propose(self, state: FilterState, z: Tensor, rows: Tensor, t: int) -> Proposal:
        return Proposal(*self.filter.update(state, z, self.noise(t)[1]))

    def commit(self, state: FilterState, z: Tensor, rows: Tensor, proposal: Proposal, t: int) -> tuple[FilterState, Tensor]:
        return proposal.state, rows

    def record(self, *args: Any) -> None:
        pass


class _KalmanSteps(FilterSteps):
    """:class:`FilterSteps` of :meth:`KalmanFilter.run`: its noise (constant or per step), the
    per-step output series it stores and the stretch prediction."""

    def __init__(self, filt: KalmanFilter, noise: NoiseParameters, shape: tuple[int, int], dtype: torch.dtype,
                 device: torch.device, tracked: bool, store_covariances: bool, store_innovations: bool) -> None:
        super().__init__(filt)
        (batch, steps), m, k, n = shape, filt.innovation_dim, filt.covariance_dim, filt.model.state_dim
        self.constant_noise = (noise.process, noise.measurement, noise.initial)
        self.per_step = [(p.process, p.measurement, p.initial) for p in noise.steps()] if noise.time_varying else None
        self.noise_parameters = noise
        self.means = _StepOutputs(steps, (batch, n), dtype, tracked)
        self.covariances = _StepOutputs(steps, (batch, k, k), dtype, tracked) if store_covariances else None
        self.innovations = _StepOutputs(steps, (batch, m), dtype, tracked) if store_innovations else None
        self.innovation_covs = _StepOutputs(steps, (batch, m, m), dtype, tracked) if store_innovations else None
        self.prior_means = _StepOutputs(steps, (batch, n), dtype, tracked) if store_innovations else None
        self.updated_steps = torch.zeros(steps, batch, dtype=torch.bool, device=device)
        self.initialised_steps = torch.zeros(steps, batch, dtype=torch.bool, device=device)
        self.no_innovation = torch.zeros(batch, m, dtype=dtype, device=device)
        self.unit_covariance = torch.eye(m, dtype=dtype, device=device).expand(batch, m, m)

    def noise(self, t: int) -> tuple[Tensor, Tensor, Tensor]:
        return self.per_step[t] if self.per_step is not None else self.constant_noise

    def record(self, t: int, prior: FilterState, state: FilterState, innovation: tuple[Tensor, Tensor] | None,
               used: Tensor, initialised: Tensor) -> None:
        if self.prior_means is not None:
            self.prior_means.put(t, prior.mean)
        self.means.put(t, state.mean)
        if self.covariances is not None:
            self.covariances.put(t, state.covariance)
        if self.innovations is not None and self.innovation_covs is not None:
            nu, S = innovation if innovation is not None else (self.no_innovation, self.unit_covariance)
            self.innovations.put(t, nu)
            self.innovation_covs.put(t, S)
        if used is not None:
            self.updated_steps[t] = used
        self.initialised_steps[t] = initialised

    def predict_steps(self, state: FilterState, t: int, count: int, dt: float) -> tuple[tuple[Tensor, Tensor | None], FilterState]:
        # the constant Q, or the steps' own stacked (B, count, k, k) (from the per-step unbind of
        # NoiseParameters.steps, whose backward is one stack, not a slice's zero-filled gradient of
        # the whole series)
        per_step_noise = self.per_step is not None and self.noise_parameters.process.dim() == 4
        process_noise = (torch.stack([self.per_step[j][0] for j in range(t, t + count)], dim=1) if per_step_noise
                         else self.noise(t)[0])
        means, covariances, state = self.filter.predict_steps(
            state, process_noise, dt, count, per_step=per_step_noise, store_covariances=self.covariances is not None)
        return (means, covariances), state

    def record_stretch(self, t: int, stop: int, block: tuple[Tensor, Tensor | None], state: FilterState, predicted: bool,
                       initialised: Tensor) -> None:
        block_means, block_covariances = block
        for series, values in ((self.means, block_means), (self.covariances, block_covariances), (self.prior_means, block_means)):
            if series is not None and values is not None:
                series.put_steps(t, values)
                if not predicted:  # the stretch ends the sequence: its last step is the final state
                    series.put(stop - 1, state.covariance if series is self.covariances else state.mean)
        if self.innovations is not None and self.innovation_covs is not None:
            batch, m = self.no_innovation.shape
            self.innovations.put_steps(t, self.no_innovation.expand(stop - t, batch, m))
            self.innovation_covs.put_steps(t, self.unit_covariance.expand(stop - t, batch, m, m))
        self.initialised_steps[t:stop] = initialised


class KalmanFilter(ABC):
    """A filter variant: one step's ``predict`` and ``update`` on a batch, and the recursion.

    Subclasses set ``name``, ``model`` (a :class:`~fkn_bench.models.base.StateSpaceModel`) and
    ``layout`` (the :class:`NoiseLayout` of their ``Q``, ``R`` and ``P0``).
    """

    name: str
    model: StateSpaceModel
    layout: NoiseLayout
    gate: float | None = None
    """Chi-square innovation gate (:meth:`set_gate`): None uses every usable measurement."""
    _gate_threshold: float = math.inf

    def set_gate(self, level: float | None) -> None:
        """Gate measurement updates at chi-square probability ``level`` (e.g. 0.999), or not at
        all (None): an update whose normalised innovation squared ``nu^T S^-1 nu`` exceeds the
        ``level`` quantile of the chi-square distribution with ``m`` degrees of freedom (``m`` the
        innovation dimension, 6 for a pose) is skipped, as an unusable measurement is (the
        documented rule), so that a gross outlier does not pull the state (Bar-Shalom, Li &
        Kirubarajan, *Estimation with Applications to Tracking and Navigation*, 2001, sec. 2.5.3
        and 5.4: the validation gate). A consistent filter rejects a fraction ``1 - level`` of
        good measurements. :data:`GATE_REINITIALISE_AFTER` consecutive rejections re-initialise
        the sequence from the last one (a lost track)."""
        self.gate, self._gate_threshold = gate_threshold(level, self.innovation_dim)

    @property
    def covariance_dim(self) -> int:
        """Dimension ``k`` of the covariance the filter carries."""
        return self.model.state_dim

    @property
    def innovation_dim(self) -> int:
        return self.model.measurement_dim

    @abstractmethod
    def predict(self, state: FilterState, process_noise: Tensor, dt: float) -> FilterState:
        """One prediction over ``dt`` seconds with process noise ``Q`` ``(k, k)`` or
        ``(B or 1, k, k)``; the predicted covariance is exactly symmetric (symmetrised). Pure, and
        the same code for torch tensors (batched, differentiable) and numpy arrays (online)."""

    @abstractmethod
    def update(self, state: FilterState, z: Tensor, measurement_noise: Tensor) -> tuple[FilterState, Tensor, Tensor]:
        """One measurement update of every batch row with ``z (B, m)`` (usable: sanitised); pure,
        numpy or torch.

        Returns the posterior state, the innovation ``(B, m)`` and its covariance ``(B, m, m)``;
        both covariances exactly symmetric (the posterior symmetrised).
        """

    def predict_steps(
        self, state: FilterState, process_noise: Tensor, dt: float, count: int, *, per_step: bool = False,
        store_covariances: bool = True,
    ) -> tuple[Tensor, Tensor | None, FilterState]:
        """``count`` predictions in a row (torch; :meth:`run` predicts a stretch of steps without
        a measurement, and the step after it, this way): ``process_noise`` as :meth:`predict`'s
        at every step or, with ``per_step``, one per step ``(B or 1, count, k, k)``. Returns the
        means ``(count - 1, B, n)`` and covariances ``(count - 1, B, k, k)`` (None unless
        ``store_covariances``) of the states before the last, and the last state. This one calls
        :meth:`predict` ``count`` times; a variant may do it in one call (the EKF's compiled
        kernels)."""
        means, covariances = [], []
        for j in range(count):
            if j:
                means.append(state.mean)
                if store_covariances:
                    covariances.append(state.covariance)
            state = self.predict(state, process_noise[:, j] if per_step else process_noise, dt)
        stack = lambda values, last: torch.stack(values) if values else last.new_empty((0, *last.shape))  # noqa: E731
        return stack(means, state.mean), stack(covariances, state.covariance) if store_covariances else None, state

    def initial_state(self, z: Tensor, initial_covariance: Tensor) -> FilterState:
        """State initialised from measurements ``z (B, m)`` (numpy or torch)."""
        mean = self.model.initial_state(z)
        k = initial_covariance.shape[-1]
        return FilterState(mean, namespace(mean).broadcast_to(initial_covariance, (mean.shape[0], k, k)))

    def prior(self, batch: int, initial_covariance: Tensor, dtype: Any) -> FilterState:
        """State reported before a sequence's first measurement (numpy for a numpy ``dtype``)."""
        mean = self.model.prior_state(batch, dtype)
        if not isinstance(initial_covariance, np.ndarray):  # (a model's prior is on the CPU)
            mean = mean.to(initial_covariance.device)
        k = initial_covariance.shape[-1]
        return FilterState(mean, namespace(mean).broadcast_to(initial_covariance, (batch, k, k)))

    def run(
        self,
        noise: NoiseParameters,
        measurements: Float[Tensor, "B T m"],
        mask: Bool[Tensor, "B T"],
        *,
        dt: float,
        initial: FilterState | None = None,
        store_covariances: bool = True,
        store_innovations: bool = True,
    ) -> FilterResult:
        """Filter a batch of sequences (see module docstring).

        Args:
            noise: ``Q``, ``R``, ``P0`` with leading axes ``()``, ``(B,)`` or ``(B, T)``.
            measurements: ``(B, T, m)``; entries outside ``mask`` are ignored (may be NaN).
            mask: ``(B, T)`` bool, True where a measurement exists.
            dt: step length, s (finite and > 0, else ``ValueError``).
            initial: start every sequence from this state at ``t = 0`` instead of initialising
                from its first measurement.
            store_covariances, store_innovations: keep per-step covariances / innovations.
        """
        if measurements.dim() != 3 or measurements.shape[-1] != self.model.measurement_dim:
            raise ValueError(
                f"measurements must have shape (B, T, {self.model.measurement_dim}) (got {tuple(measurements.shape)})"
            )
        if mask.shape != measurements.shape[:2]:
            raise ValueError(f"mask must have shape {tuple(measurements.shape[:2])} (got {tuple(mask.shape)})")
        batch, steps, _ = measurements.shape
        dtype, device = measurements.dtype, measurements.device
        if not dtype.is_floating_point:
            raise ValueError(f"measurements must be floating point (got {dtype})")
        if batch == 0 or steps == 0:
            raise ValueError(f"measurements hold no sequences or no time steps (shape {tuple(measurements.shape)})")
        dt = check_dt(dt)
        _check_noise_shapes(noise, batch, steps, self.covariance_dim, self.innovation_dim)
        noise = noise.to(dtype, device)
        time_varying = noise.time_varying
        z_all, usable = self.model.sanitize(measurements, mask.bool())

        if initial is None:
            starts = None  # (each row's first usable measurement)
            state = self.prior(batch, (noise.at_step(0) if time_varying else noise).initial, dtype)
            initialised = torch.zeros(batch, dtype=torch.bool, device=device)
        else:
            starts = torch.zeros_like(usable)
            # symmetrised once: the structured EKF predict keeps a symmetric P symmetric, and makes
            # no symmetrising pass of its own (a symmetric P is returned unchanged, to the bit)
            state = FilterState(initial.mean.to(device, dtype), symmetrize(initial.covariance.to(device, dtype)))
            initialised = torch.ones(batch, dtype=torch.bool, device=device)
        tracked = torch.is_grad_enabled() and any(
            t.requires_grad for t in (noise.process, noise.measurement, noise.initial, measurements)
        ) or (initial is not None and (initial.mean.requires_grad or initial.covariance.requires_grad))
        steps_ = _KalmanSteps(self, noise, (batch, steps), dtype, device, tracked, store_covariances, store_innovations)
        final = scan(steps_, start_carry(steps_, state, initialised), z_all, usable, dt, starts=starts)
        state = final.state
        means, covariances, innovations, innovation_covs, prior_means = (
            steps_.means, steps_.covariances, steps_.innovations, steps_.innovation_covs, steps_.prior_means)
        updated_steps, initialised_steps = steps_.updated_steps, steps_.initialised_steps
        batch_first = lambda outputs: None if outputs is None else outputs.result().transpose(0, 1)  # noqa: E731
        return FilterResult(
            means=batch_first(means),
            covariances=batch_first(covariances),
            innovations=batch_first(innovations),
            innovation_covariances=batch_first(innovation_covs),
            prior_means=batch_first(prior_means),
            updated=updated_steps.transpose(0, 1),
            initialised=initialised_steps.transpose(0, 1),
            final=FilterState(state.mean, state.covariance.contiguous()),  # (the structured step's is a view)
        )
