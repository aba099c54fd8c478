"""Regression gates for CI: accuracy against the committed leaderboard, speed as ratios.

* :mod:`~fkn_bench.gates.accuracy`: :func:`~fkn_bench.gates.accuracy.run_accuracy_gate`
  recomputes the first seeds of every committed (estimator, scenario) pair with the harness and
  compares every deterministic metric with the committed value within stated tolerances; every
  registered estimator must have committed results.
* :mod:`~fkn_bench.gates.speed`: :class:`~fkn_bench.gates.speed.RatioCheck` times code under test
  against a fixed reference in the same process and gates on their ratio, never on a stored time.

``tests/gates`` runs both in the default test command; README ("Benchmarks and CI gates") says how
to accept intended changes and how to add an estimator.
"""
