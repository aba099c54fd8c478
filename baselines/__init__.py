"""Baseline estimators and the committed learned-parameter files (``fkn_bench.baselines``).

Online adaptive filters, on the paper's additive EKF (estimate the noise while filtering; no
training):

* ``sage-husa`` (:mod:`~fkn_bench.baselines.sage_husa`): Sage & Husa (1969) covariance matching
  with a forgetting factor, eigenvalue clamping;
* ``akhlaghi`` (:mod:`~fkn_bench.baselines.akhlaghi`): Akhlaghi, Zhou & Huang (2017),
  residual-based ``R`` and innovation-based ``Q``;
* ``vbakf`` (:mod:`~fkn_bench.baselines.vbakf`): Huang et al. (2018, IEEE TAC 63(2)),
  variational Bayes with inverse-Wishart priors on ``P-`` and ``R``.

They share one batched numpy recursion (:mod:`~fkn_bench.baselines.adaptive`) over the filter
core's models and EKF step functions, run on numpy arrays.

Offline-tuned constant filters (:mod:`~fkn_bench.baselines.tuned`), refitted by
``fkn-bench train --estimator NAME --scenario S`` and run from ``params/<name>-<family>.json``:

* ``nll-tuned-ekf``: the 20 standard deviations by innovation maximum likelihood (no truth);
* ``direct-tuned-ekf``: the 20 standard deviations by the state MSE against the truth
  (EKFNet-style; the best constant-parameter filter).

:mod:`~fkn_bench.baselines.registration` registers all five with the estimator registry.
"""
