"""Registration of the Gymnasium environment ids (done when ``fkn_bench`` is imported).

Gymnasium 1.x does not load plugins from entry points, so use ``import fkn_bench`` first, or
``gym.make("fkn_bench:AstrobeeTumble-v0")`` which imports the module itself.
"""

from __future__ import annotations

import gymnasium as gym

__all__ = ["register_environments", "ENV_IDS"]

_ENTRY_POINTS: dict[str, dict[str, str]] = {
    "AstrobeeTumble-v0": {
        "entry_point": "fkn_bench.envs.astrobee_tumble:AstrobeeTumbleEnv",
        "vector_entry_point": "fkn_bench.envs.astrobee_tumble_vector:AstrobeeTumbleVectorEnv",
    },
    # a recording replayed through the estimator loop (fkn_bench.recordings); no vector version
    "AstrobeeReplay-v0": {"entry_point": "fkn_bench.envs.astrobee_replay:AstrobeeReplayEnv"},
}

ENV_IDS: tuple[str, ...] = tuple(_ENTRY_POINTS)


def register_environments() -> None:
    """Register the environment ids; a second call is a no-op."""
    for env_id, entry_points in _ENTRY_POINTS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, disable_env_checker=False, **entry_points)
