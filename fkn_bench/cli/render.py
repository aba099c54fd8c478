"""``fkn-bench render``: watch an estimator in ``AstrobeeTumble-v0``, as a picture or a video.

The estimator runs online (``reset``/``step``) in the environment with
``render_mode="rgb_array"``, its estimate being the action; the frames show the body axes of the
true attitude (solid), the estimate (dashed) and the latest measurement (dotted), the attitude
and position errors, and the attitude error over time (:mod:`fkn_bench.envs.rendering`).

``--out`` decides what is written: ``.png`` the last frame; ``.gif`` or ``.mp4`` a video of
every ``--every``-th frame at the scenario's rate (``.mp4`` needs imageio-ffmpeg: ``pip install
"fkn-bench[video]"``).

Examples::

    fkn-bench render --estimator manual-ekf --scenario tumble-fast --steps 400 --out frame.png
    fkn-bench render --estimator flexkalmannet --steps 600 --every 5 --out ds1.gif
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from fkn_bench.cli import UsageError, usage_errors
from fkn_bench.cli.options import add_command, add_scenario_file_option, check_minimum, load_scenario_files

__all__ = ["add_parser", "render_frames"]

FORMATS = (".png", ".gif", ".mp4")


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(subparsers, "render", "a picture or video of an estimator in AstrobeeTumble-v0", __doc__)
    parser.add_argument("--estimator", default="manual-ekf", help="estimator (default: manual-ekf)")
    parser.add_argument("--scenario", default="ds1", help="scenario (default: ds1)")
    parser.add_argument("--seed", type=int, default=0, help="episode seed (default: 0)")
    parser.add_argument("--steps", type=int, default=300, metavar="N", help="environment steps (default: 300)")
    parser.add_argument("--every", type=int, default=1, metavar="K", help="a video frame every K steps (default: 1)")
    parser.add_argument("--out", required=True, type=Path, metavar="FILE",
                        help="FILE.png (the last frame), FILE.gif or FILE.mp4 (a video)")
    add_scenario_file_option(parser)
    parser.set_defaults(handler=run)


def render_frames(estimator_name: str, scenario: str, seed: int, steps: int, every: int,
                  *, keep: str = "all") -> tuple[list[np.ndarray], float]:
    """Frames (``uint8 (H, W, 3)``) of ``estimator_name`` run online for ``steps`` steps of
    episode ``seed`` of ``scenario``, one every ``every`` steps and the last (``keep="last"``:
    the last only), and the frame rate (``render_fps / every``). A step whose estimate is not
    usable (non-finite: an estimator that reports nothing before its first measurement) is shown
    as the identity attitude at the origin."""
    import gymnasium as gym

    from fkn_bench.estimators import make_estimator

    env = gym.make("AstrobeeTumble-v0", scenario=scenario, render_mode="rgb_array")
    try:
        estimator = make_estimator(estimator_name, scenario=env.unwrapped.scenario)
        steps = min(steps, env.unwrapped.scenario.n_steps - 1)
        observation, _ = env.reset(seed=seed)
        estimator.reset(dt=env.unwrapped.scenario.dt)
        frames: list[np.ndarray] = []
        for k in range(steps):
            mean = np.asarray(estimator.step(observation).mean, dtype=np.float64)
            if not (np.isfinite(mean).all() and np.any(mean[:4])):  # no usable estimate yet: shown as identity
                mean = np.r_[1.0, np.zeros(12)]
            observation, *_ = env.step(mean)
            if keep == "all" and (k % every == 0 or k == steps - 1):
                frames.append(env.render())
        if keep == "last":
            frames.append(env.render())
        return frames, env.unwrapped.metadata["render_fps"] / every
    finally:
        env.close()


def _write(path: Path, frames: list[np.ndarray], fps: float) -> None:
    from fkn_bench.io import atomic_path

    if path.suffix == ".png":
        from matplotlib.image import imsave

        with atomic_path(path, ".png") as tmp:
            imsave(tmp, frames[-1], format="png")
        return
    try:
        import imageio.v3 as iio
    except ImportError:
        raise UsageError(f"--out {path}: writing a video needs imageio: pip install \"fkn-bench[video]\"") from None
    options: dict[str, Any] = {"duration": 1000.0 / fps, "loop": 0} if path.suffix == ".gif" else {"fps": fps}
    path.parent.mkdir(parents=True, exist_ok=True)
    try:  # written beside the target under its own name (ffmpeg picks the format by it), then moved
        with tempfile.TemporaryDirectory(prefix=f".{path.name}.", dir=path.parent) as scratch:
            tmp = Path(scratch) / path.name
            iio.imwrite(tmp, np.stack(frames), extension=path.suffix, **options)
            os.replace(tmp, path)
    except (ImportError, RuntimeError, BrokenPipeError) as exc:  # no ffmpeg plugin for .mp4
        raise UsageError(f"--out {path}: cannot write {path.suffix} ({' '.join(str(exc).split())[:200]}); "
                         "pip install \"fkn-bench[video]\", or use .gif") from None


def run(args: argparse.Namespace) -> int:
    from fkn_bench.estimators import UnknownEstimatorError

    check_minimum(args, seed=0, steps=1, every=1)
    if args.out.suffix.lower() not in FORMATS:
        raise UsageError(f"--out must end in {', '.join(FORMATS)} (got {args.out})")
    if args.out.is_dir():
        raise UsageError(f"--out: {args.out} is a directory, not a file")
    load_scenario_files(args)
    with usage_errors(UnknownEstimatorError, ValueError):
        frames, fps = render_frames(args.estimator, args.scenario, args.seed, args.steps, args.every,
                                    keep="last" if args.out.suffix.lower() == ".png" else "all")
    with usage_errors(OSError):
        _write(args.out, frames, fps)
    height, width, _ = frames[-1].shape
    what = "frame" if args.out.suffix.lower() == ".png" else f"{len(frames)} frames at {fps:g} fps"
    print(f"wrote {args.out} ({what}, {width}x{height}) of {args.estimator} on {args.scenario} seed {args.seed}",
          file=sys.stderr)
    return 0
