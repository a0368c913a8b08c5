"""The task ladder and the training preset: a learnable task beside the paper's.

The paper's reward, -J_i, stays every scenario's default and the figure every evaluation reports.
:data:`TRAINING_PRESET` is the named training task of the episode layer: the bounded reward
``"train"`` (:mod:`uav_formation_env.core.training_reward`), the velocity action mode, the route
offset in the observation, collisions that end the episode and a mission corridor. Every view and
trainer sees it through the scenario (``parallel_env(name, reward="train")``,
:func:`training_scenario`, the Gymnasium id ``uav_formation_env/FormationTrain-v0``), unpatched.

:data:`LADDER` lists the tasks from easy to the paper's and the distributions; docs/training.md
documents the reward's terms and the ladder.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

from uav_formation_env.config import TRAINING_PRESET, EpisodeConfig, Scenario
from uav_formation_env.config_io import resolve_scenario, with_overrides

__all__ = ["LADDER", "TRAINING_PRESET", "evaluation_scenario", "training_scenario"]

# from easy to hard: keep the formation; the paper's route; the paper; the scene distributions
LADDER: tuple[str, ...] = ("hold", "track", "paper", "random_fields", "random_swarm")


def training_scenario(
    scenario: str | Path | Scenario | Mapping[str, Any] = "paper", **overrides: Any
) -> Scenario:
    """A scenario (name, YAML path, mapping or object) under :data:`TRAINING_PRESET`, then
    ``overrides`` (double-underscore paths, validated like the scenario)."""
    return with_overrides(resolve_scenario(scenario), {**TRAINING_PRESET, **overrides})


def evaluation_scenario(scenario: Scenario) -> Scenario:
    """``scenario`` as every evaluation flies it: acceleration actions, no corridor, collisions
    reported without ending the episode (an obstacle collision is a UAV inside it, whatever
    margin ``collision.obstacle_distance`` trained with), the observation and the world kept.
    The reward stays the training reward if it is one (unterminated, it scores any policy, the
    references included, on the same scale), else -J_i. J_i is recorded either way. A policy
    trained in the velocity mode flies it through
    :class:`~uav_formation_env.policies.action_modes.VelocitySetpointPolicy`."""
    episode = EpisodeConfig()
    if scenario.episode.reward == "train":
        episode = EpisodeConfig(reward="train", train=scenario.episode.train)
    collision = replace(scenario.collision, mode="none", obstacle_distance=0.0)
    return replace(scenario, episode=episode, collision=collision)
