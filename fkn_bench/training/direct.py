"""Filter parameters optimised directly: a free unconstrained vector (EKFNet-style).

X. Xu and R. Niu (2021), "EKFNet: learning system noise statistics from measurement data",
ICASSP: the noise parameters themselves are the trainable variables, optimised through the
differentiable filter. With the supervised objective this gives the best constant-parameter
filter on the training data; with the innovation NLL it is maximum-likelihood noise
identification without ground truth.
"""

from __future__ import annotations

from torch import Tensor, nn

from fkn_bench.filters import ParameterSet
from fkn_bench.training.data import Sequences
from fkn_bench.training.trainer import NoiseModel

__all__ = ["DirectParameters"]


class DirectParameters(NoiseModel):
    """A learnable unconstrained parameter vector, the same for every sequence.

    Args:
        parameter_set: which parameters are learned, and their positivity map.
        initial_std: starting standard deviations by entry (default: the set's fixed values,
            i.e. the paper's manual tuning).
    """

    def __init__(self, parameter_set: ParameterSet, **initial_std: list[float]) -> None:
        super().__init__()
        self.parameter_set = parameter_set
        self.raw = nn.Parameter(parameter_set.initial_values(**initial_std))

    def window_raw(self, sequences: Sequences) -> Tensor:
        return self.raw.expand(sequences.batch_size, -1)

    def deployed_raw(self) -> Tensor:
        return self.raw

    def extra_repr(self) -> str:
        return f"size={self.parameter_set.size}"


