"""KalmanNet's gain network has architecture 2's layout (Revach et al. 2022, its figure of architecture 2), starts
from the documented priors, and is a pure step (no recurrent state kept on the module)."""

from __future__ import annotations

import torch

from fkn_bench.kalmannet import GainNetwork, Hidden, normalize_features


def test_layers_have_the_papers_dimensions() -> None:
    n, m, in_mult, out_mult = 12, 6, 5, 10
    net = GainNetwork(n, m, in_mult=in_mult, out_mult=out_mult)
    assert (net.gru_q.input_size, net.gru_q.hidden_size) == (n * in_mult, n * n)  # Q-GRU <- FC5(F3)
    assert (net.gru_sigma.input_size, net.gru_sigma.hidden_size) == (n * n + n * in_mult, n * n)  # <- [Q, FC6(F4)]
    assert (net.gru_s.input_size, net.gru_s.hidden_size) == (m * m + 2 * m * in_mult, m * m)  # <- [FC1, FC7(F1, F2)]
    assert (net.fc1[0].in_features, net.fc1[0].out_features) == (n * n, m * m)
    assert (net.fc7[0].in_features, net.fc7[0].out_features) == (2 * m, 2 * m * in_mult)
    assert (net.fc2[0].in_features, net.fc2[0].out_features, net.fc2[2].out_features) == (n * n + m * m, (n * n + m * m) * out_mult, n * m)
    assert (net.fc3[0].in_features, net.fc3[0].out_features) == (m * m + n * m, n * n)
    assert (net.fc4[0].in_features, net.fc4[0].out_features) == (2 * n * n, n * n)


def test_hidden_states_start_at_the_priors_and_the_step_is_pure() -> None:
    torch.manual_seed(0)
    net = GainNetwork(3, 2, in_mult=2, out_mult=2, dtype=torch.float64)
    hidden = net.initial_hidden(4)
    assert torch.equal(hidden.q, torch.eye(3).reshape(1, 9).expand(4, 9).double())
    assert torch.equal(hidden.sigma, torch.zeros(4, 9, dtype=torch.float64))
    assert torch.equal(hidden.s, torch.eye(2).reshape(1, 4).expand(4, 4).double())
    features = [torch.randn(4, k, dtype=torch.float64) for k in (2, 2, 3, 3)]
    before = {k: v.clone() for k, v in net.state_dict().items()}
    gain, after = net(*features, hidden)
    again, _ = net(*features, hidden)
    assert gain.shape == (4, 3, 2) and torch.equal(gain, again)
    assert isinstance(after, Hidden) and [h.shape for h in after] == [(4, 9), (4, 9), (4, 4)]
    assert all(torch.equal(before[k], v) for k, v in net.state_dict().items())


def test_initial_gain_and_output_scale_set_the_starting_gain() -> None:
    torch.manual_seed(0)
    start = torch.eye(3, 2, dtype=torch.float64) * 0.5
    net = GainNetwork(3, 2, in_mult=2, out_mult=2, dtype=torch.float64, initial_gain=start, output_scale=0.0)
    gain, _ = net(*(torch.randn(5, k, dtype=torch.float64) for k in (2, 2, 3, 3)), net.initial_hidden(5))
    assert torch.equal(gain, start.expand(5, 3, 2))


def test_features_are_l2_normalised_and_zero_stays_zero_with_finite_gradients() -> None:
    x = torch.tensor([[3.0, 4.0], [0.0, 0.0]], dtype=torch.float64, requires_grad=True)
    y = normalize_features(x)
    assert torch.allclose(y, torch.tensor([[0.6, 0.8], [0.0, 0.0]], dtype=torch.float64))
    y.sum().backward()
    assert torch.isfinite(x.grad).all()
