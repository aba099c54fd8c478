"""Baseline estimators and the committed learned-parameter files (``fkn_bench.baselines``)."""
