"""Simulation of a tumbling Astrobee and its Gymnasium environments (``fkn_bench.envs``)."""

from fkn_bench.envs.episodes import Episodes, EpisodeStream, generate_episodes, initial_states

__all__ = ["Episodes", "EpisodeStream", "generate_episodes", "initial_states"]
