"""Fixtures of the reporting tests: the harness tests' short scenarios, test estimators and small
stored grid (:mod:`tests.harness.conftest`), which the tables and figures are drawn from."""

from __future__ import annotations

from tests.harness.conftest import short_ds1, short_ds2, small_results_dir, test_estimators

__all__ = ["short_ds1", "short_ds2", "small_results_dir", "test_estimators"]
