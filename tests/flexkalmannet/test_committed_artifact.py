"""The committed FlexKalmanNet parameters: they load, they are what their recorded training
configuration produces, and they beat the manual tuning.

Retraining uses the committed configuration and seed. On the machine and library versions that
produced the artefact the result is identical; elsewhere floating-point differences in BLAS can
move the optimisation slightly, hence the stated tolerances: 5% on each learned standard
deviation and 2% on the test 13-state RMSE.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fkn_bench.estimators import make_estimator
from fkn_bench.flexkalmannet import FlexKalmanNetConfig, FlexKalmanNetEstimator, train_flexkalmannet
from fkn_bench.scenarios import get_scenario
from fkn_bench.training.artifacts import artifact_path, read_artifact

SIGMA_TOLERANCE = 0.05
TEST_RMSE_TOLERANCE = 0.02


@pytest.mark.parametrize("family", ["ds1", "ds2"])
def test_committed_artifacts_load_and_run_out_of_the_box(family: str) -> None:
    artifact = read_artifact(artifact_path("flexkalmannet", family))
    assert artifact["family"] == family
    assert {"git_commit", "torch", "numpy", "command", "created_utc"} <= set(artifact["provenance"])
    estimator = make_estimator("flexkalmannet", scenario=get_scenario(family))
    assert isinstance(estimator, FlexKalmanNetEstimator)
    manual = make_estimator("manual-ekf")
    assert np.all(estimator.q_std < manual.q_std * 10)  # sane magnitudes, all positive
    assert artifact["training"]["test_rmse"] < 0.9 * 0.0186  # below the manual EKF's ds1 test RMSE


@pytest.mark.slow
def test_retraining_with_the_committed_seed_reproduces_the_committed_ds1_parameters(tmp_path: Path) -> None:
    committed = read_artifact(artifact_path("flexkalmannet", "ds1"))
    config = FlexKalmanNetConfig.from_dict(committed["training"]["config"])
    scenario = get_scenario(committed["scenario"]["name"])
    assert scenario.config_hash() == committed["scenario"]["config_hash"], "the ds1 scenario changed since training"
    outcome = train_flexkalmannet(scenario, config, out=tmp_path, progress=False, plots=False)
    retrained = read_artifact(outcome.artifact)
    for entry in ("q_std", "r_std"):
        np.testing.assert_allclose(
            retrained["estimator_config"][entry], committed["estimator_config"][entry], rtol=SIGMA_TOLERANCE
        )
    assert outcome.test["test_rmse"] == pytest.approx(committed["training"]["test_rmse"], rel=TEST_RMSE_TOLERANCE)
