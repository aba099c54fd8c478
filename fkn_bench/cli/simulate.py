"""``fkn-bench simulate``: generate an episode of a scenario and print a summary of it."""

from __future__ import annotations

import argparse
import json

import numpy as np

from fkn_bench.cli.options import add_scenario_file_option, check_minimum, load_scenario_files

__all__ = ["add_parser", "episode_summary"]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("simulate", help="generate an episode and summarise it", description=__doc__)
    parser.add_argument("--scenario", default="ds1", help="scenario name (default: ds1)")
    parser.add_argument("--seed", type=int, default=0, help="episode seed (default: 0)")
    parser.add_argument("--split", default="full", choices=("full", "train", "val", "test"))
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    add_scenario_file_option(parser)
    parser.set_defaults(handler=run)


def _rms_max(errors: np.ndarray) -> dict[str, float | None]:
    if not len(errors):
        return {"rms": None, "max": None}
    return {"rms": float(np.sqrt(np.mean(errors**2))), "max": float(errors.max())}


def episode_summary(scenario_name: str, seed: int, split: str) -> dict:
    """Summary statistics of one generated episode (JSON-compatible)."""
    from fkn_bench.envs import generate_episodes
    from fkn_bench.geometry import quaternion as quat

    episodes = generate_episodes(scenario_name, [seed], split=split)
    sc = episodes.scenario
    truth, meas, valid = episodes.truth[0], episodes.measurements[0], episodes.valid[0]
    rate = np.linalg.norm(truth[:, 7:10], axis=1)
    m = meas[valid]
    attitude_error = np.degrees(quat.angle_between(truth[valid, :4], m[:, :4]))
    position_error = np.linalg.norm(m[:, 4:] - truth[valid, 4:7], axis=1)
    flipped = np.sum(np.sum(m[:, :4] * truth[valid, :4], axis=1) < 0)
    return {
        "scenario": sc.name,
        "seed": seed,
        "split": split,
        "config_hash": sc.config_hash(),
        "dynamics": sc.dynamics,
        "steps": episodes.n_steps,
        "dt_s": sc.dt,
        "duration_s": float(episodes.n_steps * sc.dt),
        "measurements": int(valid.sum()),
        "measurement_fraction": float(valid.mean()),
        "rate_norm_rad_s": {"min": float(rate.min()), "max": float(rate.max())},
        "initial_attitude_wxyz": truth[0, :4].round(6).tolist(),
        "initial_position_m": truth[0, 4:7].round(6).tolist(),
        "measured_attitude_error_deg": _rms_max(attitude_error),
        "measured_position_error_m": _rms_max(position_error),
        "sign_flipped_quaternions": int(flipped),
    }


def run(args: argparse.Namespace) -> int:
    from fkn_bench.scenarios import get_scenario

    check_minimum(args, seed=0)
    load_scenario_files(args)
    get_scenario(args.scenario)  # unknown names exit with code 2 and the list
    summary = episode_summary(args.scenario, args.seed, args.split)
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    print(f"Scenario {summary['scenario']} (seed {summary['seed']}, {summary['split']} split, "
          f"config {summary['config_hash']})")
    print(f"  dynamics            {summary['dynamics']}, |w| in [{summary['rate_norm_rad_s']['min']:.4f}, "
          f"{summary['rate_norm_rad_s']['max']:.4f}] rad/s")
    print(f"  samples             {summary['steps']} x {summary['dt_s']} s = {summary['duration_s']:.0f} s")
    print(f"  measurements        {summary['measurements']} ({100 * summary['measurement_fraction']:.1f}% of steps)")
    att, pos = summary["measured_attitude_error_deg"], summary["measured_position_error_m"]
    if att["rms"] is not None:
        print(f"  attitude noise      rms {att['rms']:.2f} deg, max {att['max']:.2f} deg")
        print(f"  position noise      rms {pos['rms']:.3f} m, max {pos['max']:.3f} m")
    print(f"  sign-flipped q      {summary['sign_flipped_quaternions']}")
    print(f"  initial attitude    {summary['initial_attitude_wxyz']} (wxyz)")
    print(f"  initial position    {summary['initial_position_m']} m")
    return 0
