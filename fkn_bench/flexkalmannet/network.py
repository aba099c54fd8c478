"""FlexKalmanNet's deep fully connected network and how it yields filter parameters.

The network (FlexKalmanNet section 3 and Table I: input 7, output 20, hidden 512, 7 layers,
LeakyReLU, no dropout) maps one pose measurement to one vector of unconstrained filter
parameters; a :class:`~fkn_bench.filters.ParameterSet` turns that vector into ``Q``, ``R`` (and
optionally ``P0`` or full Cholesky factors) through its positivity map. The recursion stays in
the filter: the network is purely feed-forward.

Input: the measured quaternion with its sign made canonical (``w >= 0``: ``q`` and ``-q`` are one
attitude, so they must give one output) and the position z-scored with the training data's mean
and standard deviation (the paper's normalisation; the statistics are buffers of the model).

How a set of measurements becomes one parameter set (a documented choice): the *masked mean of
the per-measurement unconstrained outputs* (missing measurements excluded). With the default log
positivity map this is the geometric mean of the per-measurement standard deviations. A training
window's parameters are that mean over the window (over ``samples_per_window`` randomly chosen
valid measurements of it, when set, to bound the network's cost); the deployed constant
parameters are that mean over the whole training split (Table IV of the paper lists them). In the
time-varying mode each step gets the mean over the last ``history`` valid measurements up to it,
which turns the network into an adaptive filter.

``layers`` counts the hidden layers (each ``Linear`` then the activation, then dropout when
> 0), followed by the output ``Linear``. Its bias starts at the unconstrained values of the
parameter set's starting standard deviations (the paper's manual tuning) and its weights at a
small scale, so training starts from the manual filter.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal

import torch
from torch import Tensor, nn

from fkn_bench.filters import ParameterSet
from fkn_bench.training.data import Sequences
from fkn_bench.training.trainer import NoiseModel
from fkn_bench.types import Bool, Float

__all__ = ["ACTIVATIONS", "FlexKalmanNetwork", "FlexKalmanNet", "Mode", "Screen"]

ACTIVATIONS: dict[str, type[nn.Module]] = {
    "leaky_relu": nn.LeakyReLU,
    "relu": nn.ReLU,
    "elu": nn.ELU,
    "gelu": nn.GELU,
    "tanh": nn.Tanh,
}

Mode = Literal["constant", "time_varying"]

Screen = Callable[[Tensor], Tensor]
"""``outputs (N, size) -> (N,)`` bool: which measurements' network outputs may count."""

_OUTPUT_WEIGHT_SCALE = 1e-3


class FlexKalmanNetwork(nn.Module):
    """The fully connected network: ``(..., 7)`` measurements -> ``(..., output_size)``.

    Args:
        output_size: number of unconstrained parameters (the parameter set's ``size``).
        initial_output: starting output (the output bias), ``(output_size,)``.
        position_mean, position_std: z-score statistics of the training positions, m.
        hidden, layers, activation, dropout: architecture (see module docstring).
        dtype: the network's dtype (float32 by default; the filter runs in float64).
        output_scale: factor on the output layer's initial weights.
    """

    def __init__(
        self,
        output_size: int,
        *,
        initial_output: Tensor,
        position_mean: Tensor,
        position_std: Tensor,
        hidden: int = 512,
        layers: int = 7,
        activation: str = "leaky_relu",
        dropout: float = 0.0,
        dtype: torch.dtype = torch.float32,
        output_scale: float = _OUTPUT_WEIGHT_SCALE,
    ) -> None:
        super().__init__()
        if activation not in ACTIVATIONS:
            raise ValueError(f"unknown activation {activation!r}; valid: {', '.join(ACTIVATIONS)}")
        if hidden < 1 or layers < 1:
            raise ValueError(f"hidden and layers must be >= 1 (got {hidden}, {layers})")
        if not 0.0 <= dropout < 1.0:
            raise ValueError(f"dropout must be in [0, 1) (got {dropout})")
        modules: list[nn.Module] = []
        width = 7
        for _ in range(layers):
            modules += [nn.Linear(width, hidden), ACTIVATIONS[activation]()]
            if dropout > 0:
                modules.append(nn.Dropout(dropout))
            width = hidden
        output = nn.Linear(width, output_size)
        with torch.no_grad():
            output.weight.mul_(output_scale)
            output.bias.copy_(initial_output)
        modules.append(output)
        self.layers = nn.Sequential(*modules).to(dtype)
        self.register_buffer("position_mean", torch.as_tensor(position_mean, dtype=dtype).clone())
        self.register_buffer("position_std", torch.as_tensor(position_std, dtype=dtype).clone())

    def normalise(self, measurements: Tensor) -> Tensor:
        """Canonical-sign quaternion and z-scored position; NaN (missing) entries become 0."""
        z = torch.nan_to_num(measurements.to(self.position_mean.dtype), nan=0.0, posinf=0.0, neginf=0.0)
        q = torch.where(z[..., :1] < 0, -z[..., :4], z[..., :4])
        r = (z[..., 4:7] - self.position_mean) / self.position_std
        return torch.cat((q, r), dim=-1)

    def forward(self, measurements: Tensor) -> Tensor:
        return self.layers(self.normalise(measurements))


class FlexKalmanNet(NoiseModel):
    """FlexKalmanNet as a :class:`~fkn_bench.training.NoiseModel`: network + parameter set.

    Args:
        parameter_set: which filter parameters the network outputs (default in the factory:
            the paper's 20 standard deviations).
        network: the :class:`FlexKalmanNetwork`.
        reference: training measurements ``(N, 7)`` (valid ones) over which the deployed
            parameters are averaged.
        mode: ``constant`` (paper) or ``time_varying``.
        samples_per_window: measurements per training window fed to the network (None: all).
        history: time-varying mode: valid measurements averaged per step.
        seed: seed of the window subsampling (its generator's state goes into training checkpoints
            with every other generator's: :meth:`~fkn_bench.training.Trainer.state_dict`, so that a
            resumed training picks the samples the uninterrupted one picks).
    """

    def __init__(
        self,
        parameter_set: ParameterSet,
        network: FlexKalmanNetwork,
        reference: Tensor,
        *,
        mode: Mode = "constant",
        samples_per_window: int | None = 64,
        history: int = 50,
        seed: int = 0,
    ) -> None:
        super().__init__()
        if mode not in ("constant", "time_varying"):
            raise ValueError(f"mode must be 'constant' or 'time_varying' (got {mode!r})")
        if reference.dim() != 2 or reference.shape[-1] != 7 or reference.shape[0] == 0:
            raise ValueError(f"reference measurements must have shape (N, 7), N > 0 (got {tuple(reference.shape)})")
        self.parameter_set = parameter_set
        self.network = network
        self.mode = mode
        self.samples_per_window = samples_per_window
        self.history = int(history)
        self.register_buffer("reference", reference.to(network.position_mean.dtype).clone())
        self._generator = torch.Generator().manual_seed(seed)

    def _outputs(self, measurements: Tensor) -> Tensor:
        return self.network(measurements).to(torch.float64)

    def window_raw(self, sequences: Sequences) -> Tensor:
        z, mask = sequences.measurements, sequences.mask
        if self.mode == "time_varying":
            return self.time_varying_raw(z, mask)
        if self.samples_per_window is None or self.samples_per_window >= z.shape[1]:
            outputs = self._outputs(z)
            weights = mask.to(outputs.dtype)
        else:
            # choose samples_per_window valid steps per window (random keys, invalid ones last)
            # (drawn on the CPU generator whatever the device: the same picks on every device)
            keys = torch.rand(mask.shape, generator=self._generator, device="cpu").to(mask.device) + (~mask).to(torch.float64) * 2.0
            picked = keys.argsort(dim=1)[:, : self.samples_per_window]
            chosen = torch.gather(z, 1, picked[..., None].expand(-1, -1, 7))
            outputs = self._outputs(chosen)
            weights = torch.gather(mask, 1, picked).to(outputs.dtype)
        count = weights.sum(1, keepdim=True)
        if bool((count == 0).any()):
            raise ValueError("a training window has no valid measurement")
        return (outputs * weights[..., None]).sum(1) / count

    def time_varying_raw(self, measurements: Float[Tensor, "B T 7"], mask: Bool[Tensor, "B T"], *,
                         screen: Screen | None = None) -> Float[Tensor, "B T size"]:
        """Per-step parameters ``(B, T, size)``: the mean over the last ``history`` valid
        measurements up to each step (the deployed parameters before the first one).

        The network runs on the ``N`` valid measurements of ``mask`` only (one step in ten on
        ds1): the other steps' outputs carry zero weight in the window mean, so evaluating them
        would take ``B T / N`` times the network passes for the same result. ``screen`` (deployment): ``outputs (N, size) -> (N,)`` True where a
        measurement's output may count; the others are left out as if missing."""
        valid = self._outputs(measurements[mask])  # (N, size), row-major order of the mask
        if screen is not None:
            trusted = screen(valid)
            if not bool(trusted.all()):
                kept = mask.clone()
                kept[mask] = trusted
                mask, valid = kept, valid[trusted]
        outputs = valid.new_zeros(mask.shape + valid.shape[-1:])
        outputs = outputs.masked_scatter(mask[..., None].expand_as(outputs), valid)
        weights = mask.to(outputs.dtype)
        running = torch.cumsum(outputs * weights[..., None], dim=1)  # sum of outputs up to t
        counts = torch.cumsum(weights, dim=1)  # measurements up to t
        prefix = torch.cat((torch.zeros_like(running[:, :1]), running), dim=1)
        dropped = (counts - self.history).clamp_min(0)  # measurements that left the window
        # step at which the `dropped`-th measurement arrived: first step where counts >= dropped
        step = torch.searchsorted(counts.contiguous(), dropped.contiguous(), right=False)
        index = torch.where(dropped > 0, step + 1, torch.zeros_like(step))
        window_sum = running - torch.gather(prefix, 1, index[..., None].expand_as(running))
        window_count = counts - dropped
        safe = torch.where(window_count > 0, window_count, torch.ones_like(window_count))
        deployed = self.deployed_raw().expand_as(running)
        return torch.where(window_count[..., None] > 0, window_sum / safe[..., None], deployed)

    def deployed_raw(self) -> Tensor:
        """The mean output over the reference measurements. Outside autograd it is cached until a
        weight, buffer or the train/eval mode changes (tensor version counters: an optimiser step
        or ``load_state_dict`` bumps them): an epoch asks for it three times (validation, the
        history's standard deviations, the checkpoint), and each is a network pass over the
        ``(R, 7)`` reference measurements."""
        if torch.is_grad_enabled():
            return self._outputs(self.reference).mean(0)
        key = (self.training, *((t.data_ptr(), t._version) for t in (*self.parameters(), *self.buffers())))
        cached = getattr(self, "_deployed_cache", None)
        if cached is None or cached[0] != key:
            cached = (key, self._outputs(self.reference).mean(0))
            self._deployed_cache = cached
        return cached[1]

    @property
    def deploys_network(self) -> bool:
        """The time-varying mode deploys the network (per-step parameters), the constant mode its
        mean output."""
        return self.mode == "time_varying"

    def sequence_raw(self, measurements: Tensor, mask: Tensor, *, screen: Screen | None = None) -> Tensor:
        """Per-step parameters in the time-varying mode (missing or non-finite measurements carry
        no weight; ``screen`` as in :meth:`time_varying_raw`), else the constant deployed ones."""
        if self.mode != "time_varying":
            return self.deployed_raw()
        usable = mask & torch.isfinite(measurements).all(-1)
        z = torch.where(usable[..., None], measurements, torch.zeros_like(measurements))
        return self.time_varying_raw(z, usable, screen=screen)
