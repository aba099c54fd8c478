"""Regression gates for CI, run by ``tests/gates`` in the default test command (README, "Benchmarks
and CI gates", says how to accept intended changes and how to add an estimator):

* :mod:`~fkn_bench.gates.accuracy`: recompute the first seeds of the committed leaderboard's
  cells and compare every deterministic metric within stated tolerances;
* :mod:`~fkn_bench.gates.speed`: time code under test against a fixed reference in the same
  process and gate on their ratio, never on a stored time.
"""
