"""KalmanNet's gain network, architecture 2 (Revach et al. 2022, "Architecture 2" and its figure).

Three GRUs track quantities shaped like the Kalman filter's second-order moments: ``Q`` (the
process noise), ``Sigma`` (the predicted state covariance) and ``S`` (the innovation covariance),
with hidden sizes ``n^2``, ``n^2`` and ``m^2`` (``n``: state tangent dimension, ``m``: measurement
tangent dimension). Fully connected layers FC1-FC7 connect them (dimensions as in the paper's
figure, ``in_mult`` and ``out_mult`` its input and output multipliers):

==========  =================================  ==============================  =============
layer       input                              output                          activation
==========  =================================  ==============================  =============
FC5         F3 (n)                             n * in_mult                     ReLU
Q-GRU       FC5 (n * in_mult)                  hidden n^2                      GRU
FC6         F4 (n)                             n * in_mult                     ReLU
Sigma-GRU   [Q-GRU, FC6] (n^2 + n * in_mult)   hidden n^2                      GRU
FC1         Sigma-GRU (n^2)                    m^2                             ReLU
FC7         [F1, F2] (2m)                      2m * in_mult                    ReLU
S-GRU       [FC1, FC7] (m^2 + 2m * in_mult)    hidden m^2                      GRU
FC2         [Sigma-GRU, S-GRU] (n^2 + m^2)     (n^2 + m^2) * out_mult -> n m   ReLU, linear
FC3         [S-GRU, FC2] (m^2 + n m)           n^2                             ReLU
FC4         [Sigma-GRU, FC3] (2 n^2)           n^2 (the Sigma-GRU's next state) ReLU
==========  =================================  ==============================  =============

FC2's output is the gain ``K_t`` (``n x m``, row-major). FC3 and FC4 are the "backward flow":
FC4's output replaces the Sigma-GRU's hidden state for the next step, as the covariance update
``Sigma_t|t = Sigma_t|t-1 - K S K^T`` does in the Kalman filter. The features are
``F1`` observation difference, ``F2`` innovation, ``F3`` forward-evolution difference and ``F4``
forward-update difference (the paper's input features), each L2-normalised before entering the network
(:func:`normalize_features`).

The hidden states start at ``Q = I``, ``Sigma = 0``, ``S = I`` (flattened), the priors the
authors' implementation uses by default; they are buffers of the module, so a trained network carries them.
The recurrent state is never kept on the module: :meth:`GainNetwork.forward` takes the hidden
states and returns the new ones (a pure step), so that several sequences, the batch path and the
online path can run the same weights.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor, nn
from torch.nn import functional

__all__ = ["GainNetwork", "Hidden", "normalize_features"]


class Hidden(NamedTuple):
    """The three GRUs' hidden states, each ``(B, size)``: ``q (n^2)``, ``sigma (n^2)``, ``s (m^2)``."""

    q: Tensor
    sigma: Tensor
    s: Tensor


def normalize_features(feature: Tensor, eps: float = 1e-12) -> Tensor:
    """``f / max(|f|_2, eps)`` over the last axis (the paper's input features: each one is
    L2-normalised; a zero feature stays zero, with finite gradients)."""
    return functional.normalize(feature, p=2.0, dim=-1, eps=eps)


def _dense(inputs: int, outputs: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(inputs, outputs), nn.ReLU())


class GainNetwork(nn.Module):
    """Architecture 2 (see module docstring) for state tangent dimension ``n`` and measurement
    tangent dimension ``m``.

    Args:
        n, m: tangent dimensions (the gain is ``n x m``).
        in_mult, out_mult: the paper's input and output multipliers (its code's defaults 5, 40).
        dtype: the network's dtype (features are cast to it, the gain is returned in it).
        initial_gain: ``(n, m)`` gain the network starts near (FC2's output bias), or None (the
            paper: PyTorch's default initialisation everywhere).
        output_scale: factor on FC2's output-layer weights at initialisation (1: PyTorch's
            default), so that the starting gain is ``initial_gain`` plus a small learned part.
    """

    def __init__(
        self,
        n: int,
        m: int,
        *,
        in_mult: int = 5,
        out_mult: int = 40,
        dtype: torch.dtype = torch.float32,
        initial_gain: Tensor | None = None,
        output_scale: float = 1.0,
    ) -> None:
        super().__init__()
        if n < 1 or m < 1 or in_mult < 1 or out_mult < 1:
            raise ValueError(f"n, m, in_mult and out_mult must be >= 1 (got {n}, {m}, {in_mult}, {out_mult})")
        self.n, self.m, self.in_mult, self.out_mult = int(n), int(m), int(in_mult), int(out_mult)
        n2, m2 = n * n, m * m
        self.fc5 = _dense(n, n * in_mult)
        self.gru_q = nn.GRUCell(n * in_mult, n2)
        self.fc6 = _dense(n, n * in_mult)
        self.gru_sigma = nn.GRUCell(n2 + n * in_mult, n2)
        self.fc1 = _dense(n2, m2)
        self.fc7 = _dense(2 * m, 2 * m * in_mult)
        self.gru_s = nn.GRUCell(m2 + 2 * m * in_mult, m2)
        hidden_fc2 = (n2 + m2) * out_mult
        self.fc2 = nn.Sequential(nn.Linear(n2 + m2, hidden_fc2), nn.ReLU(), nn.Linear(hidden_fc2, n * m))
        if initial_gain is not None or output_scale != 1.0:
            with torch.no_grad():
                last = self.fc2[-1]
                last.weight.mul_(output_scale)
                if initial_gain is not None:
                    if tuple(initial_gain.shape) != (n, m):
                        raise ValueError(f"initial_gain must be ({n}, {m}) (got {tuple(initial_gain.shape)})")
                    last.bias.copy_(initial_gain.reshape(-1))
        self.fc3 = _dense(m2 + n * m, n2)
        self.fc4 = _dense(2 * n2, n2)
        self.register_buffer("prior_q", torch.eye(n).reshape(-1))
        self.register_buffer("prior_sigma", torch.zeros(n2))
        self.register_buffer("prior_s", torch.eye(m).reshape(-1))
        self.to(dtype)

    @property
    def dtype(self) -> torch.dtype:
        return self.prior_q.dtype

    def initial_hidden(self, batch: int) -> Hidden:
        """The hidden states of a sequence's start (the priors ``Q = I``, ``Sigma = 0``, ``S = I``)."""
        return Hidden(*(p.expand(batch, -1) for p in (self.prior_q, self.prior_sigma, self.prior_s)))

    def forward(self, f1: Tensor, f2: Tensor, f3: Tensor, f4: Tensor, hidden: Hidden) -> tuple[Tensor, Hidden]:
        """One step: normalised features ``F1 (B, m)``, ``F2 (B, m)``, ``F3 (B, n)``, ``F4 (B, n)``
        and the hidden states -> the gain ``(B, n, m)`` and the next hidden states."""
        f1, f2, f3, f4 = (f.to(self.dtype) for f in (f1, f2, f3, f4))
        h_q = self.gru_q(self.fc5(f3), hidden.q)  # Q: the state's evolution (F3)
        h_sigma = self.gru_sigma(torch.cat((h_q, self.fc6(f4)), dim=-1), hidden.sigma)  # Sigma: Q and the update (F4)
        h_s = self.gru_s(torch.cat((self.fc1(h_sigma), self.fc7(torch.cat((f1, f2), dim=-1))), dim=-1), hidden.s)
        gain = self.fc2(torch.cat((h_sigma, h_s), dim=-1))
        backward = self.fc3(torch.cat((h_s, gain), dim=-1))
        sigma_next = self.fc4(torch.cat((h_sigma, backward), dim=-1))
        return gain.reshape(-1, self.n, self.m), Hidden(h_q, sigma_next, h_s)
