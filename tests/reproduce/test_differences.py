"""The generated "differences from the paper" follow the numbers they are given."""

from __future__ import annotations

from types import SimpleNamespace

from fkn_bench.reporting.reference import PAPER_LEARNED_STD
from fkn_bench.reproduce.differences import Context, differences
from fkn_bench.reproduce.evaluation import Evaluation
from fkn_bench.types import STATE_NAMES


def _evaluation(label: str, scenario: str, scale: float, *, omega: float | None = None, unstable: float = 0.0) -> Evaluation:
    base = {n: 0.02 * scale for n in STATE_NAMES}
    base.update({n: 0.001 * scale for n in ("vx", "vy", "vz")})
    if omega is not None:
        base.update({n: omega for n in ("wx", "wy", "wz")})
    return Evaluation(
        estimator=label, scenario=scenario, seeds=(0, 1), state_rmse=0.018 * scale, component_rmse=base,
        group_rmse={"attitude": 5.0, "position": 0.04, "omega": 0.01, "velocity": 0.002}, settling_time_s=12.0,
        settled_fraction=1.0, diverged_fraction=unstable, divergence_reasons={"error_growth": unstable},
        unstable_fraction=unstable,
    )


def _trained(q_scale: float) -> SimpleNamespace:
    stds = {k: v * (q_scale if k.startswith("sigma_Q") else 1.0) for k, v in PAPER_LEARNED_STD["ds1"].items()}
    return SimpleNamespace(best_epoch=10, epochs_run=30, best_val_rmse=0.015 * q_scale, test_rmse=0.016 * q_scale,
                           seconds_per_epoch=1.5, learned_std=stds)


def _context(learned_scale: float, *, unstable: float = 0.0, ds2_param_scale: float = 1.2) -> Context:
    evaluations = {}
    for scenario in ("ds1", "ds2", "ds1-noise5x", "ds1-gap100"):
        evaluations[("manual", scenario)] = _evaluation("manual", scenario, 1.0, omega=0.008)
        evaluations[("oracle", scenario)] = _evaluation("oracle", scenario, 0.7)
        evaluations[("learned-ds1", scenario)] = _evaluation("learned-ds1", scenario, learned_scale, omega=0.002 * learned_scale,
                                                             unstable=unstable if scenario != "ds1" else 0.0)
    evaluations[("learned-ds1", "ds2")] = _evaluation("learned-ds1", "ds2", learned_scale * 1.3)
    evaluations[("learned-ds2", "ds2")] = _evaluation("learned-ds2", "ds2", learned_scale)
    evaluations[("learned-ds2", "ds1")] = _evaluation("learned-ds2", "ds1", learned_scale * ds2_param_scale)
    return Context(
        trained={"ds1": _trained(1.0), "ds2": _trained(3.0)},
        evaluations=evaluations,
        true_std={f"sigma_R_{n}": 0.04 for n in ("qw", "qx", "qy", "qz")},
        uncertainty_steps=120.0,
        uncertainty_window=500,
        quick=False,
        config_summary="test config",
    )


def test_a_better_learned_filter_agrees_with_the_paper() -> None:
    text = "\n".join(differences(_context(0.5)))
    assert "This agrees with the paper." in text
    assert "Our manual EKF already beats the paper's learned one" in text
    assert "position RMSEs" in text  # our positions (0.02 m) are far below the paper's 0.10 m
    assert "DS2's own parameters" in text and "both as the paper describes" in text
    assert "no run blew up" in text
    assert "Learning beats the true noise" in text
    assert "QUICK RUN" not in text


def test_a_worse_learned_filter_is_reported_as_not_reproducing() -> None:
    bullets = differences(_context(1.5, unstable=0.5, ds2_param_scale=0.9))
    text = "\n".join(bullets)
    assert "does not reproduce the paper's claim" in text
    assert "some runs blew up" in text
    assert "one of the two as the paper describes" in text
    assert "Learning beats the true noise" not in text


def test_equal_filters_say_the_gain_is_not_reproduced() -> None:
    context = _context(1.0)
    manual = context.evaluations[("manual", "ds1")]
    evaluations = dict(context.evaluations)
    evaluations[("learned-ds1", "ds1")] = Evaluation(**{**manual.__dict__, "estimator": "learned-ds1"})
    text = "\n".join(differences(Context(**{**context.__dict__, "evaluations": evaluations, "quick": True})))
    assert "the paper's gain is not reproduced" in text
    assert text.startswith("**QUICK RUN.**")
