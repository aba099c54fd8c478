"""The speed-ratio gate: each timed workload against a fixed reference run beside it.

Absolute timings on shared machines vary by tens of percent between identical runs (measured
here), so this gate never compares a time with a stored one. Each :class:`RatioCheck` times the code
under test (the *candidate*) and a fixed *reference* that does the same work the plain way, in
the same process, interleaved, and gates on ``ratio = reference time / candidate time`` (how many
times faster the candidate is than its reference; higher is better). The reference of
``ekf-forward``, ``ukf-forward``, ``mekf-forward`` (a batched torch filter's ``run()`` on 16
sequences x 100 steps of ds1), ``ekf-forward-backward`` (the EKF's ``run()`` and the gradient of a
loss with respect to ``log sigma_Q``) and ``online-step:<estimator>`` (``reset()`` + 200 ``step()``
calls of a registered estimator) is :func:`numpy_ekf_loop`, the paper's EKF in numpy, one sequence
and one step at a time, forward only; ``train-epoch`` times one :class:`~fkn_bench.training.Trainer`
epoch of a small FlexKalmanNet (8 windows of 150) against one window of the sequential reference
trainer (:mod:`fkn_bench.flexkalmannet.reference`), scaled to the epoch.

Measurement (:func:`measure_ratio`): both workloads are built once (data generation and model
construction are not timed) and run once untimed; then ``repeats`` rounds each time the reference
and the candidate once, alternating which goes first. Times are CPU seconds of this process
(:func:`time.process_time`): on a shared 2-core machine the wall time of a 100 ms call depends
mostly on how the scheduler shares the cores with other processes, which CPU time leaves out (the
workloads are CPU-bound; a regression that adds threads shows up in it too), and Python's
garbage collector is paused inside each timed call, as :mod:`timeit` does. Interference that
remains (caches, memory bandwidth, a sibling hyperthread) varies from moment to moment; the two
calls of one round run back to back under nearly the same interference, so the gated ratio is
the *median of the per-round ratios* (the ratio of the two minimum times would pair the luckiest
rounds of either side, from different moments, and let a doubled implementation pass).

Gate (:func:`evaluate`): a check passes when its ratio is at least ``min_ratio``. A check below it
is measured again, up to ``attempts`` times in all, and fails only when every attempt is below: a
real slowdown is below on every attempt, a burst of interference rarely is. ``min_ratio`` is about
0.7 of the ratio measured on the project's 2-core CI machine (:data:`MEASURED`), so that noise
does not cross it while a 2x slowdown of the candidate, which halves the ratio, does.
``fkn-bench bench gate --trips`` (what CI runs after the tests) shows both: the real code passes
an evaluation, and the same code made to do its work twice (:func:`doubled` on
:attr:`RatioCheck.hotspot`) fails (:func:`trips`, one check per hotspot: :func:`trip_checks`).
The gate is a benchmark, not a test: its verdicts rest on timings, which a loaded machine moves
(a test run's other worker, another process), so the test command runs it as its own step, on a
machine with nothing else to do, and ``tests/gates/test_speed_gate.py`` checks only what does not
depend on time (the thresholds against :data:`MEASURED`, the reference's numbers, the commands).

Ratios depend somewhat on the machine (numpy's and torch's per-call overheads differ between
CPUs and builds): on another machine, print them with ``fkn-bench bench gate`` and adjust.
"""

from __future__ import annotations

import dataclasses
import gc
import importlib
import statistics
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from fkn_bench.types import ArrayB, ArrayF

__all__ = [
    "Workloads",
    "RatioCheck",
    "RatioMeasurement",
    "GateOutcome",
    "MEASURED",
    "ONLINE_STEP_MIN_RATIOS",
    "DEFAULT_ONLINE_STEP_MIN_RATIO",
    "builtin_checks",
    "online_step_check",
    "estimator_checks",
    "all_checks",
    "gated_checks",
    "trip_checks",
    "trips",
    "measure_ratio",
    "evaluate",
    "calibrate",
    "doubled",
    "format_outcomes",
    "numpy_ekf_loop",
    "forward_backward_workload",
]

Workload = Callable[[], Any]


@dataclass(frozen=True)
class Workloads:
    """What a check's ``setup`` builds: two zero-argument callables doing the same work, and the
    factor that scales one reference call to one candidate call's work (the sequential trainer
    times one window of an eight-window epoch: 8)."""

    reference: Workload
    candidate: Workload
    reference_scale: float = 1.0


def _second(first: Any, second: Any) -> Any:
    return second


@dataclass(frozen=True)
class RatioCheck:
    """One gated ratio (see module docstring).

    Attributes:
        name: e.g. ``ekf-forward``.
        description: what is timed against what.
        setup: builds the :class:`Workloads` (not timed).
        min_ratio: the gate: ``reference time / candidate time`` must be at least this.
        hotspot: ``"module:Class.method"`` or ``"module:function"`` that carries the candidate's
            work: :func:`doubled` makes it run twice, a deliberately slowed implementation.
        combine: how the doubled hotspot combines its two results (default: the second; the
            forward-backward check averages them, so that the backward pass runs through both).
        repeats: rounds per measurement.
    """

    name: str
    description: str
    setup: Callable[[], Workloads]
    min_ratio: float
    hotspot: str = ""
    combine: Callable[[Any, Any], Any] = _second
    repeats: int = 7


@dataclass(frozen=True)
class RatioMeasurement:
    """One measurement of a check: the minimum CPU seconds of each side over the rounds (the
    reference's scaled to the candidate's work), and the per-round ratios, whose median is the
    measured :attr:`ratio` (module docstring)."""

    check: str
    reference_seconds: float
    candidate_seconds: float
    round_ratios: tuple[float, ...]

    @property
    def ratio(self) -> float:
        return float(statistics.median(self.round_ratios))

    def to_dict(self) -> dict[str, Any]:
        return {"check": self.check, "reference_seconds": self.reference_seconds,
                "candidate_seconds": self.candidate_seconds, "ratio": self.ratio,
                "round_ratios": list(self.round_ratios)}


@dataclass(frozen=True)
class GateOutcome:
    """The gate's verdict on one check: every attempt's measurement; passed when the last one
    reached ``min_ratio`` (attempts stop at the first that does)."""

    check: RatioCheck
    attempts: tuple[RatioMeasurement, ...] = field(default_factory=tuple)

    @property
    def ratio(self) -> float:
        return self.attempts[-1].ratio

    @property
    def passed(self) -> bool:
        return bool(self.attempts) and self.ratio >= self.check.min_ratio

    def to_dict(self) -> dict[str, Any]:
        return {"check": self.check.name, "min_ratio": self.check.min_ratio, "passed": self.passed,
                "attempts": [a.to_dict() for a in self.attempts]}


# ---------------------------------------------------------------------------------- measuring
def _cpu_seconds(work: Workload) -> float:
    """CPU seconds of ``work()``, with Python's cyclic garbage collector paused (as :mod:`timeit`
    does: a collection inside a few-millisecond call would dominate it)."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        began = time.process_time()
        work()
        return time.process_time() - began
    finally:
        if enabled:
            gc.enable()


def measure_ratio(check: RatioCheck, *, repeats: int | None = None, workloads: Workloads | None = None) -> RatioMeasurement:
    """Time ``check`` once (module docstring); ``workloads`` reuses already built ones."""
    from fkn_bench.runtime import torch_threads

    rounds = check.repeats if repeats is None else int(repeats)
    if rounds < 1:
        raise ValueError(f"repeats must be >= 1 (got {rounds})")
    with torch_threads():
        built = workloads if workloads is not None else check.setup()
        built.reference()  # warm-up: caches, allocator, lazy imports
        built.candidate()
        gc.collect()
        reference_times: list[float] = []
        candidate_times: list[float] = []
        sides = ((reference_times, built.reference), (candidate_times, built.candidate))
        for index in range(rounds):  # alternating which goes first
            for times, work in sides if index % 2 == 0 else sides[::-1]:
                times.append(_cpu_seconds(work))
    scale = built.reference_scale
    return RatioMeasurement(
        check=check.name,
        reference_seconds=scale * min(reference_times),
        candidate_seconds=min(candidate_times),
        round_ratios=tuple(scale * r / max(c, 1e-12) for r, c in zip(reference_times, candidate_times)),
    )


def _build(check: RatioCheck) -> Workloads:
    from fkn_bench.runtime import torch_threads

    with torch_threads():
        return check.setup()


def evaluate(check: RatioCheck, *, attempts: int = 3, repeats: int | None = None, workloads: Workloads | None = None) -> GateOutcome:
    """Measure ``check`` until its ratio reaches ``min_ratio``, at most ``attempts`` times (the
    workloads are built once); the outcome holds every measurement."""
    if attempts < 1:
        raise ValueError(f"attempts must be >= 1 (got {attempts})")
    workloads = workloads if workloads is not None else _build(check)
    done: list[RatioMeasurement] = []
    for _ in range(attempts):
        done.append(measure_ratio(check, repeats=repeats, workloads=workloads))
        if done[-1].ratio >= check.min_ratio:
            break
    return GateOutcome(check, tuple(done))


@contextmanager
def doubled(hotspot: str, combine: Callable[[Any, Any], Any] = _second) -> Iterator[None]:
    """Within the block, ``hotspot`` (``"module:Class.method"`` or ``"module:function"``) does its
    work twice and returns ``combine(first, second)``: a deliberately slowed implementation, to
    show that the gate trips. A method inherited by ``Class`` is shadowed on ``Class`` only."""
    module_name, _, qualified = hotspot.partition(":")
    if not module_name or not qualified:
        raise ValueError(f"hotspot must be 'module:name' or 'module:Class.method' (got {hotspot!r})")
    owner: Any = importlib.import_module(module_name)
    *path, attribute = qualified.split(".")
    for part in path:
        owner = getattr(owner, part)
    own = attribute in vars(owner)
    original = vars(owner)[attribute] if own else getattr(owner, attribute)
    if isinstance(original, (staticmethod, classmethod)):
        raise TypeError(f"{hotspot}: static and class methods are not supported")

    def twice(*args: Any, **kwargs: Any) -> Any:
        first = original(*args, **kwargs)
        return combine(first, original(*args, **kwargs))

    setattr(owner, attribute, twice)
    try:
        yield
    finally:
        if own:
            setattr(owner, attribute, original)
        else:
            delattr(owner, attribute)


def average_filter_results(first: Any, second: Any) -> Any:
    """``combine`` for a doubled ``run()``: the second result with the mean of both results'
    means, so that gradients flow through both recursions."""
    return dataclasses.replace(second, means=0.5 * (first.means + second.means))


def calibrate(check: RatioCheck, *, runs: int = 10, doubled_runs: int = 4) -> dict[str, float]:
    """Measure ``check`` ``runs`` times, and ``doubled_runs`` times with its hotspot doubled; returns
    a :data:`MEASURED` entry plus ``suggested_min_ratio`` (0.7 of the median, rounded to two
    significant digits). Run it on the machine the gate runs on, as the gate sees it (quiet:
    the test command runs the gate after pytest, with nothing else running)."""
    workloads = _build(check)
    normal = [measure_ratio(check, workloads=workloads).ratio for _ in range(runs)]
    slow: list[float] = []
    if check.hotspot and doubled_runs:
        with doubled(check.hotspot, check.combine):
            slow = [measure_ratio(check, workloads=workloads).ratio for _ in range(doubled_runs)]
    median = statistics.median(normal)
    entry = {"median": median, "min": min(normal), "max": max(normal), "n": len(normal),
             "suggested_min_ratio": float(f"{0.7 * median:.2g}")}
    if slow:
        entry.update(doubled_median=statistics.median(slow), doubled_max=max(slow))
    return entry


# ---------------------------------------------------------------------------------- reference
def numpy_ekf_loop(measurements: ArrayF, valid: ArrayB, Q: ArrayF, R: ArrayF, P0: ArrayF, dt: float) -> ArrayF:
    """The plain reference: the paper's EKF one sequence and one step at a time in numpy, written
    here on purpose apart from the filters (the gate's yardstick must not move when they do),
    with the batched filter's rules (initialise at the first usable measurement, then predict
    every step and update where a measurement is usable). ``measurements (B, T, 7)``,
    ``valid (B, T)``; returns the means ``(B, T, 13)``."""
    from scipy.linalg import lapack

    A = np.eye(13)
    A[4:7, 10:13] = dt * np.eye(3)
    basis = np.zeros((13, 4, 13))  # x @ basis = dt/2 [Omega(w) | 0 | Theta(q) | 0] (4 x 13)
    for i in range(4):
        w_, x_, y_, z_ = np.eye(4)[i]
        basis[i, :, 7:10] = ((-x_, -y_, -z_), (w_, z_, -y_), (-z_, w_, x_), (y_, -x_, w_))
    for i in range(3):
        a, b, c = np.eye(3)[i]
        basis[7 + i, :, 0:4] = ((0, -a, -b, -c), (a, 0, -c, b), (b, c, 0, -a), (c, -b, a, 0))
    basis = (0.5 * dt) * basis.reshape(13, 52)
    flip = np.array([-1.0] * 4 + [1.0] * 3)
    eye4, gain_template = np.eye(4), np.concatenate((np.eye(13), np.zeros((13, 7))), axis=1)  # [I | 0]
    batch, steps, _ = measurements.shape
    means = np.zeros((batch, steps, 13))
    means[:, :, 0] = 1.0
    for b in range(batch):
        x: ArrayF | None = None
        P = P0
        for t in range(steps):
            z = measurements[b, t] if valid[b, t] else None
            if z is not None:
                norm = float(np.sqrt(z[0:4] @ z[0:4])) if np.isfinite(z).all() else 0.0
                z = np.concatenate((z[0:4] / norm, z[4:7])) if 1e-6 <= norm < np.inf else None
            if x is None:
                if z is None:
                    continue
                x, P = np.concatenate((z, np.zeros(6))), P0
            else:
                rows = (x @ basis).reshape(4, 13)
                x_new = A @ x
                x_new[0:4] += rows[:, 0:4] @ x[0:4]
                F = A.copy()
                F[0:4] += rows
                x, P = x_new, F @ P @ F.T + Q
                P = 0.5 * (P + P.T)
                if z is not None:
                    z = z * flip if z[0:4] @ x[0:4] < 0.0 else z
                    factor, _ = lapack.dpotrf(P[0:7, 0:7] + R, lower=1, clean=0)
                    Kt, _ = lapack.dpotrs(factor, P[0:7], lower=1)  # K^T = S^-1 H P
                    x = x + (z - x[0:7]) @ Kt
                    norm = float(np.sqrt(x[0:4] @ x[0:4]))
                    unit = x[0:4] / norm
                    x[0:4] = unit
                    G = gain_template.copy()  # T [I - K H | K]
                    G[:, 0:7] -= Kt.T
                    G[:, 13:20] = Kt.T
                    G[0:4] = ((eye4 - unit[:, None] * unit) / norm) @ G[0:4]
                    D = np.zeros((20, 20))
                    D[0:13, 0:13], D[13:20, 13:20] = P, R
                    P = G @ D @ G.T
                    P = 0.5 * (P + P.T)
            means[b, t] = x
    return means


@lru_cache(maxsize=4)
@lru_cache(maxsize=1)
def suite_device() -> Any:
    """The ``torch.device`` the speed suite's batched filter and training benchmarks run on:
    environment ``FKN_BENCH_DEVICE`` (``cpu`` by default; ``fkn-bench bench run --device``),
    checked by :func:`fkn_bench.runtime.resolve_device`."""
    import os

    from fkn_bench.runtime import resolve_device

    return resolve_device(os.environ.get("FKN_BENCH_DEVICE", "cpu"))


def suite_large_batch() -> int:
    """The speed suite's large batch: environment ``FKN_BENCH_LARGE_BATCH`` (1024 by default;
    ``fkn-bench bench run --large-batch``)."""
    import os

    value = os.environ.get("FKN_BENCH_LARGE_BATCH", "1024")
    if not value.isdigit() or int(value) < 1:
        raise ValueError(f"FKN_BENCH_LARGE_BATCH must be a positive integer (got {value!r})")
    return int(value)


def synchronized(call: Callable[[], Any]) -> Callable[[], Any]:
    """``call``, waiting at its end for the work it queued on :func:`suite_device` when that is
    a GPU (which runs asynchronously: a timing would otherwise measure the launch, not the work);
    ``call`` itself on the CPU."""
    device = suite_device()
    if device.type != "cuda":
        return call
    import torch

    def timed() -> Any:
        result = call()
        torch.cuda.synchronize(device)
        return result

    return timed


def episodes_for(scenario: str, batch: int, steps: int) -> tuple[ArrayF, ArrayB, float]:
    """``(measurements (B, T, 7), valid (B, T), dt)``: the first ``steps`` test-split steps of
    seeds ``0 .. batch-1`` of ``scenario`` (read-only, cached)."""
    from fkn_bench.envs import generate_episodes

    episodes = generate_episodes(scenario, batch, split="test")
    z = np.array(episodes.measurements[:, :steps])
    m = np.array(episodes.valid[:, :steps])
    z.flags.writeable = m.flags.writeable = False
    return z, m, float(episodes.scenario.dt)


def manual_noise(variant: str) -> Any:
    """The manual tuning's :class:`~fkn_bench.models.noise.NoiseParameters` of ``variant``."""
    from fkn_bench.estimators import make_estimator

    return make_estimator(f"manual-{variant}").noise_parameters()


def _numpy_reference(z: ArrayF, m: ArrayB, dt: float) -> Workload:
    noise = manual_noise("ekf")
    Q, R, P0 = (t.numpy() for t in (noise.process, noise.measurement, noise.initial))
    return lambda: numpy_ekf_loop(z, m, Q, R, P0, dt)


# ---------------------------------------------------------------------------------- checks
FILTER_BATCH = 16
"""Sequences of the filter checks (ds1, test split, seeds 0-15)."""

FILTER_STEPS = 100
"""Steps per sequence of the filter checks (10 measurements at ds1's one per 10 steps)."""


def forward_backward_workload(variant_filter: Any, noise: Any, z: Any, mask: Any, dt: float) -> Workload:
    """A call that runs ``variant_filter`` on ``z (B, T, 7)``, ``mask (B, T)`` (tensors) with the
    process noise parameterised by its log standard deviations, and returns the gradient of the
    mean squared estimate with respect to them: the forward + backward work of training."""
    import torch

    from fkn_bench.models.noise import NoiseParameters

    log_std = torch.log(torch.diagonal(noise.process)).mul(0.5).clone().requires_grad_(True)

    def forward_backward() -> Any:
        process = torch.diag_embed(torch.exp(2.0 * log_std))
        result = variant_filter.run(NoiseParameters(process, noise.measurement, noise.initial), z, mask, dt=dt,
                                    store_covariances=False, store_innovations=False)
        (gradient,) = torch.autograd.grad(result.means.square().mean(), log_std)
        return gradient

    return forward_backward


def _filter_setup(variant: str, *, backward: bool = False) -> Callable[[], Workloads]:
    def setup() -> Workloads:
        import torch

        from fkn_bench.filters import make_filter

        z, m, dt = episodes_for("ds1", FILTER_BATCH, FILTER_STEPS)
        noise = manual_noise(variant)
        variant_filter = make_filter(variant)
        zt, mt = torch.from_numpy(np.array(z)), torch.from_numpy(np.array(m))
        if backward:
            candidate = forward_backward_workload(variant_filter, noise, zt, mt, dt)
        else:
            def candidate() -> Any:
                with torch.no_grad():
                    return variant_filter.run(noise, zt, mt, dt=dt)

        return Workloads(_numpy_reference(z, m, dt), candidate)

    return setup


TRAIN_STEPS = 1500
"""ds1 shortened to this many samples for ``train-epoch`` (a 1200-sample train split)."""

TRAIN_WINDOW = 150
"""Training window of ``train-epoch``: 8 windows, one batch per epoch."""

TRAIN_REFERENCE_WINDOWS = 1
"""Windows of the sequential reference timed per round (scaled to the epoch)."""


def _train_setup() -> Workloads:
    from fkn_bench.flexkalmannet.benchmark import training_benchmark
    from fkn_bench.flexkalmannet.config import FlexKalmanNetConfig
    from fkn_bench.scenarios import get_scenario

    # pinned (not the defaults, which follow the tuning), with a small network: the gate is about
    # the training loop, not about matrix products
    config = FlexKalmanNetConfig(window=TRAIN_WINDOW, stride=None, train_measurement_every=1, episodes=1, hidden=64,
                                 layers=3, samples_per_window=16, windows_per_batch=32, lr=1e-5, loss_cut=100)
    data, trainer, reference = training_benchmark(get_scenario("ds1", n_steps=TRAIN_STEPS), config,
                                                  reference_windows=TRAIN_REFERENCE_WINDOWS)
    # run_epoch looked up at each call, so that a patched Trainer.run_epoch applies
    return Workloads(reference, lambda: trainer.run_epoch(), data.n_windows / TRAIN_REFERENCE_WINDOWS)


MEASURED: dict[str, dict[str, float]] = {
    # `fkn-bench bench gate --calibrate 6` on the 2-core AMD EPYC CI machine, quiet (as the test
    # command runs the gate: after pytest, nothing else running); 6 measurements and
    # 3 doubled per check. Thresholds: 0.7 of the median, rounded to two significant digits.
    # The filter checks and train-epoch re-measured after the structured EKF step (issue 17; it runs
    # from 128 rows, so these 16-row workloads keep the generic step, and their ratios moved by
    # less than their spread): `fkn-bench bench gate --check ekf-forward --check ukf-forward
    # --check mekf-forward --check ekf-forward-backward --check train-epoch --calibrate 6` on the
    # shared 2-core AMD machine (not quiet); the online-step entries are from before (their code
    # and the numpy reference did not change).
    # ekf-forward, ekf-forward-backward and train-epoch re-measured after the EKF step's compiled
    # CPU kernels (fkn_bench.filters.kernels, which run at any batch size: these 16-row workloads
    # included), same command with those three checks (shared machine): medians 1.351 -> 3.112,
    # 0.519 -> 1.146, 10.50 -> 15.07.
    # ekf-forward, ekf-forward-backward and train-epoch re-measured after run() predicts a stretch
    # of steps without a measurement in one call (kernels.predict_steps), same command with those
    # three checks and ukf-forward, mekf-forward (shared machine): medians 3.112 -> 5.049,
    # 1.146 -> 2.080, 15.07 -> 15.71 (threshold kept); ukf 0.519, mekf 0.665 (unchanged within
    # their spread: entries and thresholds kept).
    # ekf-forward and ekf-forward-backward re-measured on 2026-11-27 (quiet machine, `--calibrate 5`
    # with the four filter checks; ukf and mekf within their earlier spread): the doubled ratios
    # had come within 8% and 4% of the thresholds 3.5 and 1.5 (one doubled ekf-forward passed
    # in a loaded test run); thresholds set between the least real and the largest doubled ratio.
    "ekf-forward": {"median": 6.8541, "min": 5.0605, "max": 7.2018, "doubled_median": 3.2097, "doubled_max": 3.2491, "n": 5},
    "ukf-forward": {"median": 0.512, "min": 0.5091, "max": 0.5769, "doubled_median": 0.2615, "doubled_max": 0.2954, "n": 6},
    "mekf-forward": {"median": 0.6368, "min": 0.622, "max": 0.6508, "doubled_median": 0.3334, "doubled_max": 0.3398, "n": 6},
    "ekf-forward-backward": {"median": 2.7012, "min": 2.2613, "max": 2.7943, "doubled_median": 1.3129, "doubled_max": 1.4423, "n": 5},
    "train-epoch": {"median": 15.7108, "min": 15.2687, "max": 17.6752, "doubled_median": 7.7134, "doubled_max": 7.749, "n": 6},
    "online-step:manual-ekf": {"median": 0.4251, "min": 0.4127, "max": 0.4377, "doubled_median": 0.1794, "doubled_max": 0.1823, "n": 6},
    "online-step:manual-ukf": {"median": 0.1864, "min": 0.1629, "max": 0.206, "doubled_median": 0.0943, "doubled_max": 0.0992, "n": 6},
    "online-step:manual-mekf": {"median": 0.2628, "min": 0.2534, "max": 0.2745, "doubled_median": 0.1309, "doubled_max": 0.1347, "n": 6},
    "online-step:oracle-ekf": {"median": 0.4266, "min": 0.4037, "max": 0.4408, "doubled_median": 0.2267, "doubled_max": 0.2343, "n": 6},
    "online-step:flexkalmannet": {"median": 0.4131, "min": 0.3906, "max": 0.4511, "doubled_median": 0.2183, "doubled_max": 0.2274, "n": 6},
    "online-step:sage-husa-default": {"median": 0.2839, "min": 0.2574, "max": 0.3056, "doubled_median": 0.1429, "doubled_max": 0.1441, "n": 6},
    "online-step:akhlaghi-default": {"median": 0.3069, "min": 0.2666, "max": 0.3363, "doubled_median": 0.1575, "doubled_max": 0.1686, "n": 6},
    "online-step:vbakf-default": {"median": 0.2134, "min": 0.195, "max": 0.2233, "doubled_median": 0.0991, "doubled_max": 0.1059, "n": 6},
    "online-step:nll-tuned-ekf": {"median": 0.4316, "min": 0.4153, "max": 0.4798, "doubled_median": 0.2142, "doubled_max": 0.2305, "n": 6},
    "online-step:direct-tuned-ekf": {"median": 0.4314, "min": 0.3498, "max": 0.4411, "doubled_median": 0.2453, "doubled_max": 0.2529, "n": 6},
    # The online-step entries re-measured on 2026-11-27 (issue 34's session; the 2-core AMD EPYC,
    # quiet): every median had moved to about 0.77x its earlier value, at the issue's commit as at
    # this one (the numpy reference loop is faster with this machine's numpy 2.4), leaving
    # manual-ekf 1.09x and manual-ukf 1.04x above their thresholds: the gate failed at random in
    # the test command. `fkn-bench bench gate --calibrate 6` with the eleven online checks
    # (flexkalmannet-tv with --calibrate 10: its ratio spreads most); thresholds 0.7 of the median
    # (flexkalmannet-tv 0.040, between its least real ratio and its largest doubled one).
    "online-step:flexkalmannet-tv": {"median": 0.061, "min": 0.0495, "max": 0.0688, "doubled_median": 0.031, "doubled_max": 0.0315, "n": 10},
}
"""Ratios measured when the thresholds were set (see module docstring and the comment inside).

Rounds per measurement (:attr:`RatioCheck.repeats`): 7, online checks 9 (five were not enough),
train-epoch 3 (its ratios spread less than 10% around a median 1.4x its threshold)."""


def builtin_checks() -> list[RatioCheck]:
    """The filter and training checks."""
    return [
        RatioCheck("ekf-forward", "batched torch EKF forward vs the per-step numpy EKF loop",
                   _filter_setup("ekf"), min_ratio=4.2,
                   hotspot="fkn_bench.filters.ekf:ExtendedKalmanFilter.run"),
        RatioCheck("ukf-forward", "batched torch UKF forward vs the per-step numpy EKF loop",
                   _filter_setup("ukf"), min_ratio=0.36,
                   hotspot="fkn_bench.filters.ukf:UnscentedKalmanFilter.run"),
        RatioCheck("mekf-forward", "batched torch multiplicative EKF forward vs the per-step numpy EKF loop",
                   _filter_setup("mekf"), min_ratio=0.45,
                   hotspot="fkn_bench.filters.mekf:MultiplicativeEKF.run"),
        RatioCheck("ekf-forward-backward", "batched EKF forward + gradient vs the per-step numpy EKF loop",
                   _filter_setup("ekf", backward=True), min_ratio=1.8,
                   hotspot="fkn_bench.filters.ekf:ExtendedKalmanFilter.run", combine=average_filter_results),
        RatioCheck("train-epoch", "FlexKalmanNet Trainer epoch vs the sequential reference trainer",
                   _train_setup, min_ratio=11.0,
                   hotspot="fkn_bench.training.trainer:Trainer.run_epoch", repeats=3),
    ]


ONLINE_STEPS = 200
"""Steps of the online checks (ds1 test split, seed 0)."""

ONLINE_REPEATS = 9
"""Rounds per measurement of the online checks (a few milliseconds each for the numpy filters)."""

ONLINE_STEP_MIN_RATIOS: dict[str, float] = {
    "manual-ekf": 0.3,
    "manual-ukf": 0.13,
    "manual-mekf": 0.18,
    "oracle-ekf": 0.3,
    "flexkalmannet": 0.29,
    "sage-husa-default": 0.2,
    "akhlaghi-default": 0.21,
    "vbakf-default": 0.15,
    "nll-tuned-ekf": 0.3,
    "direct-tuned-ekf": 0.3,
    "flexkalmannet-tv": 0.04,  # the network on every measurement
}
"""``online-step:<estimator>`` thresholds by estimator name: the numpy loop's time over the
estimator's ``reset()`` + ``step()`` time on the same sequence must be at least this. The adaptive
filters are gated with their papers' settings (``*-default``, as calibrated): their tuned
settings run the same code with fewer iterations or one adapted matrix, and get the budget."""

DEFAULT_ONLINE_STEP_MIN_RATIO = 0.01
"""Threshold of estimators without their own entry in :data:`ONLINE_STEP_MIN_RATIOS`: at most
100x slower per step than the plain numpy EKF. A budget, not a regression detector: give an
estimator its own entry (about 0.7 of its measured ratio) to catch a 2x slowdown."""


def online_step_check(name: str, *, min_ratio: float | None = None) -> RatioCheck:
    """The ``online-step:<name>`` check of registered estimator ``name`` on ds1's measurements,
    built for ds1 or, where it does not build there, for the first named scenario it builds for
    (:func:`~fkn_bench.estimators.conformance.build_for_checks`; raises when it builds for none)."""
    from fkn_bench.estimators.conformance import build_for_checks

    cls = type(build_for_checks(name))
    if not getattr(cls, "causal", True):
        raise ValueError(f"{name} is non-causal: it has no online step to time")

    def setup() -> Workloads:
        z, m, dt = episodes_for("ds1", FILTER_BATCH, FILTER_STEPS)
        z1, m1 = z[:1, :ONLINE_STEPS], m[:1, :ONLINE_STEPS]
        estimator = build_for_checks(name)
        observations = [np.where(ok, row, np.nan) for row, ok in zip(z1[0], m1[0])]

        def candidate() -> None:
            estimator.reset(dt=dt)
            for observation in observations:
                estimator.step(observation)

        return Workloads(_numpy_reference(z1, m1, dt), candidate)

    threshold = min_ratio if min_ratio is not None else ONLINE_STEP_MIN_RATIOS.get(name, DEFAULT_ONLINE_STEP_MIN_RATIO)
    return RatioCheck(f"online-step:{name}", f"{name} reset() + step() vs the per-step numpy EKF loop", setup,
                      min_ratio=threshold, hotspot=f"{cls.__module__}:{cls.__qualname__}.step",
                      repeats=ONLINE_REPEATS)


def estimator_checks(names: Sequence[str] | None = None) -> list[RatioCheck]:
    """``online-step`` checks of ``names`` (default: every registered estimator that builds for a
    named scenario; an unavailable one, e.g. untrained, and a non-causal one, a smoother, have
    nothing to time)."""
    from fkn_bench.estimators import estimator_names

    checks = []
    for name in names if names is not None else estimator_names():
        try:
            checks.append(online_step_check(name))
        except Exception:  # noqa: BLE001 - unavailable: skipped
            continue
    return checks


def all_checks() -> list[RatioCheck]:
    """Every check: :func:`builtin_checks` then :func:`estimator_checks`."""
    return builtin_checks() + estimator_checks()


def gated_checks(checks: Sequence[RatioCheck]) -> list[RatioCheck]:
    """The checks that detect a 2x regression: the built-in ones and the online steps of the
    estimators with their own threshold (:data:`ONLINE_STEP_MIN_RATIOS`; the others get only the
    generous default budget)."""
    return [c for c in checks
            if not c.name.startswith("online-step:") or c.name.split(":", 1)[1] in ONLINE_STEP_MIN_RATIOS]


def trip_checks(checks: Sequence[RatioCheck]) -> list[RatioCheck]:
    """One gated check per hotspot (:func:`gated_checks`), to show that a 2x slower hotspot trips
    the gate: checks that slow down the same code (``ekf-forward-backward`` and ``ekf-forward``,
    the online steps of the estimators built on one class) trip alike, since every threshold is
    about 0.7 of its ratio and doubling the hotspot halves it (:data:`MEASURED` holds each check's
    doubled ratios)."""
    chosen: dict[str, RatioCheck] = {}
    for check in gated_checks(checks):
        chosen.setdefault(check.hotspot, check)
    return list(chosen.values())


def trips(check: RatioCheck, *, attempts: int = 1, workloads: Workloads | None = None) -> GateOutcome:
    """Evaluate ``check`` with its hotspot doing its work twice (:func:`doubled`); the gate works
    for it when the outcome fails. One attempt by default: a failure is what is expected, and one
    attempt is the strictest form of that check (more give a doubled hotspot more chances)."""
    workloads = workloads if workloads is not None else _build(check)
    with doubled(check.hotspot, check.combine):
        return evaluate(check, attempts=attempts, workloads=workloads)


def format_outcomes(outcomes: Sequence[GateOutcome]) -> str:
    """A plain-text table: check, ratio, threshold, per-round spread, attempts, verdict."""
    lines = [f"{'check':28s} {'ratio':>7s} {'min':>6s} {'rounds':>11s} {'tries':>5s}  verdict"]
    for outcome in outcomes:
        last = outcome.attempts[-1]
        spread = f"{min(last.round_ratios):.2f}-{max(last.round_ratios):.2f}"
        verdict = "ok" if outcome.passed else f"TOO SLOW (every attempt below {outcome.check.min_ratio:g})"
        lines.append(f"{outcome.check.name:28s} {outcome.ratio:7.3f} {outcome.check.min_ratio:6.3f} {spread:>11s} "
                     f"{len(outcome.attempts):5d}  {verdict}")
    return "\n".join(lines)
