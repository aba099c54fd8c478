"""Registration of the Gymnasium environment ids (done when ``fkn_bench`` is imported).

Gymnasium 1.x does not load plugins from entry points, so use ``import fkn_bench`` first, or
``gym.make("fkn_bench:AstrobeeTumble-v0")`` which imports the module itself.
"""

from __future__ import annotations

import gymnasium as gym

__all__ = ["register_environments", "ENV_IDS"]

ENV_IDS: tuple[str, ...] = ("AstrobeeTumble-v0", "AstrobeeReplay-v0")


def register_environments() -> None:
    """Register the environment ids; a second call is a no-op."""
    if "AstrobeeTumble-v0" not in gym.registry:
        gym.register(
            id="AstrobeeTumble-v0",
            entry_point="fkn_bench.envs.astrobee_tumble:AstrobeeTumbleEnv",
            vector_entry_point="fkn_bench.envs.astrobee_tumble_vector:AstrobeeTumbleVectorEnv",
            disable_env_checker=False,
        )
    if "AstrobeeReplay-v0" not in gym.registry:
        # a recording replayed through the estimator loop (fkn_bench.recordings); no vector version
        gym.register(
            id="AstrobeeReplay-v0",
            entry_point="fkn_bench.envs.astrobee_replay:AstrobeeReplayEnv",
            disable_env_checker=False,
        )
