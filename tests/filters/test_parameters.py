"""NoiseParameters, NoiseLayout and ParameterSet: sizes and names, positivity maps, Cholesky
factors, plain-dict round trips, errors."""

from __future__ import annotations

import json

import pytest
import torch

from fkn_bench.filters import MEKF_MANUAL_LAYOUT, ParameterSet
from fkn_bench.models import NoiseParameters
from fkn_bench.models import PAPER_MANUAL_LAYOUT
from fkn_bench.filters.parameters import LEARNABLE_ENTRIES
from fkn_bench.types import MEASUREMENT_NAMES, STATE_NAMES

PAPER_NAMES = [f"sigma_Q_{n}" for n in STATE_NAMES] + [f"sigma_R_{n}" for n in MEASUREMENT_NAMES]


def _diag(std) -> torch.Tensor:  # noqa: ANN001
    s = torch.as_tensor(std, dtype=torch.float64)
    return torch.diag(s * s)


# ---------------------------------------------------------------------------- NoiseParameters
def test_noise_parameters_from_std_to_and_at_step() -> None:
    noise = NoiseParameters.from_std([1.0, 2.0], [3.0], [0.5, 0.25])
    torch.testing.assert_close(noise.process, torch.diag(torch.tensor([1.0, 4.0], dtype=torch.float64)))
    torch.testing.assert_close(noise.measurement, torch.tensor([[9.0]], dtype=torch.float64))
    assert not noise.time_varying and noise.at_step(5) is not noise
    assert noise.to(torch.float32).process.dtype == torch.float32
    batched = NoiseParameters.from_std(torch.ones(2, 4, 2), torch.ones(1), torch.ones(2))
    assert batched.process.shape == (2, 4, 2, 2) and batched.time_varying
    step = batched.at_step(3)
    assert step.process.shape == (2, 2, 2) and step.measurement.shape == (1, 1) and not step.time_varying
    steps = NoiseParameters.from_std(torch.rand(2, 4, 2) + 0.5, torch.ones(1), torch.ones(2)).steps()
    assert len(steps) == 4


def test_steps_are_at_step_of_every_step_and_carry_the_same_gradients() -> None:
    """``steps()`` (one unbind) is ``at_step(t)`` for every ``t``, in value and in gradient."""
    std = (torch.rand(2, 5, 3, dtype=torch.float64) + 0.5).requires_grad_()
    noise = NoiseParameters.from_std(std, torch.ones(2, 5, 1, dtype=torch.float64), torch.ones(3))
    weights = torch.rand(5, 3, 3, dtype=torch.float64)
    unbound = sum((s.process * w).sum() + s.measurement.sum() for s, w in zip(noise.steps(), weights))
    (gradient,) = torch.autograd.grad(unbound, std, retain_graph=True)
    selected = sum((noise.at_step(t).process * weights[t]).sum() + noise.at_step(t).measurement.sum() for t in range(5))
    (expected,) = torch.autograd.grad(selected, std)
    torch.testing.assert_close(gradient, expected, rtol=0, atol=0)
    for t, s in enumerate(noise.steps()):
        torch.testing.assert_close(s.process, noise.at_step(t).process, rtol=0, atol=0)
        assert s.initial is noise.initial  # constant entries are shared, not copied


# ---------------------------------------------------------------------------- ParameterSet
def test_default_is_the_papers_twenty_parameters() -> None:
    parameters = ParameterSet(PAPER_MANUAL_LAYOUT)
    assert parameters.size == 20
    assert parameters.names() == PAPER_NAMES
    assert parameters.learn == ("q_std", "r_std") and parameters.positivity == "log"
    mekf = ParameterSet(MEKF_MANUAL_LAYOUT)
    assert mekf.size == 18 and mekf.names()[0] == "sigma_Q_dthx" and mekf.names()[-1] == "sigma_R_rz"


@pytest.mark.parametrize("positivity", ["log", "softplus"])
@pytest.mark.parametrize("layout", [PAPER_MANUAL_LAYOUT, MEKF_MANUAL_LAYOUT], ids=["additive", "mekf"])
def test_initial_values_invert_the_positivity_map(positivity: str, layout) -> None:  # noqa: ANN001
    parameters = ParameterSet(layout, learn=("q_std", "r_std", "p0_std"), positivity=positivity)  # type: ignore[arg-type]
    raw = parameters.initial_values()
    noise = parameters.to_noise(raw)
    torch.testing.assert_close(noise.process, _diag(layout.q_default), rtol=1e-12, atol=0)
    torch.testing.assert_close(noise.measurement, _diag(layout.r_default), rtol=1e-12, atol=0)
    torch.testing.assert_close(noise.initial, _diag(layout.p0_default), rtol=1e-12, atol=0)
    # explicit standard deviations, including tiny and large ones (softplus^-1 must stay stable)
    q = [1e-7, 1e-4, 0.005, 1.0, 30.0, 800.0] + [0.1] * (len(layout.q_default) - 6)
    noise = parameters.to_noise(parameters.initial_values(q_std=q))
    torch.testing.assert_close(noise.process, _diag(q), rtol=1e-10, atol=0)
    # the two maps differ: same raw values, different stds
    other = "softplus" if positivity == "log" else "log"
    assert not torch.allclose(ParameterSet(layout, positivity=other).to_noise(raw[: ParameterSet(layout).size]).process, _diag(layout.q_default))  # type: ignore[arg-type]


def test_fixed_entries_are_used_when_not_learned() -> None:
    fixed_r = [0.3] * 7
    parameters = ParameterSet(PAPER_MANUAL_LAYOUT, learn=("q_std",), fixed={"r_std": fixed_r})
    assert parameters.size == 13
    noise = parameters.to_noise(torch.zeros(4, 13, dtype=torch.float64))  # std = exp(0) = 1, batch of 4
    assert noise.process.shape == (4, 13, 13) and noise.measurement.shape == (4, 7, 7)
    torch.testing.assert_close(noise.process[2], torch.eye(13, dtype=torch.float64))
    torch.testing.assert_close(noise.measurement[0], _diag(fixed_r))
    torch.testing.assert_close(noise.initial[3], _diag(PAPER_MANUAL_LAYOUT.p0_default))


@pytest.mark.parametrize("positivity", ["log", "softplus"])
def test_cholesky_entries_give_spd_matrices(positivity: str) -> None:
    parameters = ParameterSet(PAPER_MANUAL_LAYOUT, learn=("q_chol", "r_chol"), positivity=positivity)  # type: ignore[arg-type]
    assert parameters.size == 13 * 14 // 2 + 7 * 8 // 2
    names = parameters.names()
    assert names[0] == "L_Q_qw_qw" and names[1] == "L_Q_qx_qw" and names[-1] == "L_R_rz_rz"
    # starts diagonal at the fixed stds
    noise = parameters.to_noise(parameters.initial_values())
    torch.testing.assert_close(noise.process, _diag(PAPER_MANUAL_LAYOUT.q_default), rtol=1e-12, atol=0)
    torch.testing.assert_close(noise.measurement, _diag(PAPER_MANUAL_LAYOUT.r_default), rtol=1e-12, atol=0)
    # any raw vector (even with very negative diagonal raw values) gives SPD matrices
    generator = torch.Generator().manual_seed(0)
    raw = torch.randn(5, parameters.size, generator=generator, dtype=torch.float64)
    noise = parameters.to_noise(raw)
    for matrix in (noise.process, noise.measurement):
        # exact on any machine: the covariance is symmetrised by construction, 0.5 (M + M^T): M[i, j]
        # and M[j, i] are then the same sum of the same two numbers (IEEE addition is commutative)
        torch.testing.assert_close(matrix, matrix.transpose(-1, -2), rtol=0, atol=0)
        assert (torch.linalg.eigvalsh(matrix) > 0).all()
        assert torch.linalg.cholesky_ex(matrix)[1].eq(0).all()
    # off-diagonal entries do couple components
    assert (noise.process[0] - torch.diag(torch.diagonal(noise.process[0]))).abs().max() > 0.1


@pytest.mark.parametrize("learn", [("q_std", "r_std"), ("q_chol", "r_std", "p0_std"), ("r_chol",), ()])
@pytest.mark.parametrize("positivity", ["log", "softplus"])
def test_dict_round_trip(learn: tuple[str, ...], positivity: str) -> None:
    parameters = ParameterSet(PAPER_MANUAL_LAYOUT, learn=learn, positivity=positivity)  # type: ignore[arg-type]
    generator = torch.Generator().manual_seed(1)
    raw = parameters.initial_values() + 0.3 * torch.randn(parameters.size, generator=generator, dtype=torch.float64)
    document = parameters.to_dict(raw)
    document = json.loads(json.dumps(document))  # plain JSON
    assert document["positivity"] == positivity and document["learned"] == list(learn)
    for name, entry in document["entries"].items():
        assert entry["labels"] == list(PAPER_MANUAL_LAYOUT.labels(name))
        assert entry["units"] == list(PAPER_MANUAL_LAYOUT.units(name))
    if "q_std" in learn:
        assert document["entries"]["q_std"]["units"][4] == "m" and document["entries"]["q_std"]["units"][7] == "rad/s"
    assert set(document["fixed"]) == {"q_std", "r_std", "p0_std"} - set(learn)
    back = parameters.from_dict(document)
    torch.testing.assert_close(back, raw, rtol=0, atol=1e-12)
    # a set with the other positivity map reads the same standard deviations
    other = ParameterSet(PAPER_MANUAL_LAYOUT, learn=learn, positivity="log" if positivity == "softplus" else "softplus")
    for a, b in zip(other.to_noise(other.from_dict(document)).__dict__.values(), parameters.to_noise(raw).__dict__.values()):
        torch.testing.assert_close(a, b, rtol=1e-10, atol=1e-300)


def test_from_dict_checks_labels_units_and_values() -> None:
    parameters = ParameterSet(PAPER_MANUAL_LAYOUT, learn=("q_std", "r_chol"))
    good = parameters.to_dict(parameters.initial_values())

    def broken(change) -> dict:  # noqa: ANN001
        document = json.loads(json.dumps(good))
        change(document)
        return document

    cases = [
        (lambda d: d["entries"].pop("q_std"), r"parameter dict has no entry 'q_std'"),
        (lambda d: d["entries"]["q_std"].__setitem__("labels", list(reversed(STATE_NAMES))), r"entry 'q_std' labels .* do not match"),
        (lambda d: d["entries"]["q_std"]["units"].__setitem__(4, "mm"), r"entry 'q_std' units .* do not match"),
        (lambda d: d["entries"]["q_std"]["std"].__setitem__(2, -0.1), r"entry 'q_std' needs 13 positive finite"),
        (lambda d: d["entries"]["q_std"]["std"].__setitem__(2, float("inf")), r"entry 'q_std': 'std' must be a list of finite"),
        # issue 34, finding 5: numbers are JSON numbers (true was read as 1.0, "0.1" as 0.1)
        (lambda d: d["entries"]["q_std"]["std"].__setitem__(2, True), r"entry 'q_std': 'std' must be .*not booleans or strings"),
        (lambda d: d["entries"]["q_std"].__setitem__("std", ["0.1"] * 13), r"entry 'q_std': 'std' must be a list of finite"),
        (lambda d: d["entries"]["r_chol"]["cholesky"][3].__setitem__(3, "1"), r"'cholesky' must be a list of lists of finite"),
        (lambda d: d["entries"]["q_std"]["std"].pop(), r"entry 'q_std' needs 13 positive finite"),
        (lambda d: d["entries"]["r_chol"]["cholesky"][3].__setitem__(3, 0.0), r"entry 'r_chol' needs a positive Cholesky diagonal"),
        (lambda d: d["entries"]["r_chol"].__setitem__("cholesky", [[1.0]]), r"entry 'r_chol' needs a 7x7"),
    ]
    for change, message in cases:
        with pytest.raises(ValueError, match=message):
            parameters.from_dict(broken(change))
    # a dict of the MEKF layout does not load into the additive set
    mekf = ParameterSet(MEKF_MANUAL_LAYOUT)
    with pytest.raises(ValueError, match="labels"):
        ParameterSet(PAPER_MANUAL_LAYOUT).from_dict(mekf.to_dict(mekf.initial_values()))


def test_bad_parameter_sets_are_refused() -> None:
    layout = PAPER_MANUAL_LAYOUT
    with pytest.raises(ValueError, match=r"fixed 'p0_std' must be numbers, not booleans or strings"):
        ParameterSet(layout, fixed={"p0_std": [True] * len(layout.p0_default)})
    with pytest.raises(ValueError, match=r"fixed 'r_std' must be numbers"):
        ParameterSet(layout, fixed={"r_std": ["0.1"] * len(layout.r_default)})
    with pytest.raises(ValueError, match=r"unknown learnable entries \['w_std'\]; valid: \["):
        ParameterSet(layout, learn=("w_std",))
    with pytest.raises(ValueError, match="learnable entries repeated"):
        ParameterSet(layout, learn=("q_std", "q_std"))
    with pytest.raises(ValueError, match="learn either 'q_std' or 'q_chol', not both"):
        ParameterSet(layout, learn=("q_std", "q_chol"))
    with pytest.raises(ValueError, match="positivity must be 'log' or 'softplus'"):
        ParameterSet(layout, positivity="exp")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="fixed 'r_std' needs 7 values"):
        ParameterSet(layout, fixed={"r_std": [0.1] * 6})
    with pytest.raises(ValueError, match="fixed 'p0_std' must be finite and > 0"):
        ParameterSet(layout, fixed={"p0_std": [0.1] * 12 + [0.0]})
    parameters = ParameterSet(layout)
    with pytest.raises(ValueError, match="expected 20 unconstrained values in the last axis"):
        parameters.to_noise(torch.zeros(19, dtype=torch.float64))
    with pytest.raises(ValueError, match="expected 20 values"):
        parameters.to_dict(torch.zeros(21, dtype=torch.float64))
    assert set(LEARNABLE_ENTRIES) == {"q_std", "r_std", "p0_std", "q_chol", "r_chol"}


def test_empty_parameter_set() -> None:
    parameters = ParameterSet(PAPER_MANUAL_LAYOUT, learn=())
    assert parameters.size == 0 and parameters.names() == []
    raw = parameters.initial_values()
    assert raw.shape == (0,)
    noise = parameters.to_noise(raw)
    torch.testing.assert_close(noise.measurement, _diag(PAPER_MANUAL_LAYOUT.r_default))
    torch.testing.assert_close(parameters.from_dict(parameters.to_dict(raw)), raw)
