"""Flying a policy trained in the velocity action mode where actions are accelerations.

A policy trained under ``episode.action = "velocity"`` (the training preset) outputs set-point
actions. :class:`VelocitySetpointPolicy` turns them into the normalised accelerations of the
paper's action space with the same inner loop the episode layer applies
(:func:`uav_formation_env.core.dynamics.velocity_setpoint_input`), reading the own and reference
velocities from the observation (slots 0:3 and 6:9 of both layouts), so that every evaluation
flies it on the paper's episode rules beside the reference policies.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from uav_formation_env.config import EpisodeConfig
from uav_formation_env.core.dynamics import velocity_setpoint_input
from uav_formation_env.core.observation import VELOCITY_SCALE

__all__ = ["VelocitySetpointPolicy", "in_acceleration_mode"]


class VelocitySetpointPolicy:
    """A set-point policy as an acceleration policy (``act_batch`` (B, N, dim) -> (B, N, 3)).

    Args:
        policy: any object with ``act_batch(obs, *args)`` giving set-point actions in [-1, 1].
        episode: the episode options it was trained under (``velocity_range``, ``velocity_gain``).
        u_max: the scenario's per-axis input bound [m/s^2].
    """

    def __init__(self, policy: Any, episode: EpisodeConfig, u_max: float) -> None:
        self.policy = policy
        self.velocity_range = episode.velocity_range
        self.velocity_gain = episode.velocity_gain
        self.u_max = u_max

    def act_batch(self, obs: np.ndarray, *args: Any, **kwargs: Any) -> np.ndarray:
        setpoint = np.clip(np.asarray(self.policy.act_batch(obs, *args, **kwargs)), -1.0, 1.0)
        obs = np.asarray(obs, dtype=np.float64)
        velocity = obs[..., 0:3] * VELOCITY_SCALE
        reference = obs[..., 6:9] * VELOCITY_SCALE
        u = velocity_setpoint_input(
            setpoint, velocity, reference, self.velocity_range, self.velocity_gain, self.u_max
        )
        return u / self.u_max

    def __getattr__(self, name: str) -> Any:
        """Everything else (``check_scenario``, ``reset``, ...) is the wrapped policy's."""
        if name == "policy":
            raise AttributeError(name)
        return getattr(self.policy, name)


def in_acceleration_mode(policy: Any, episode: EpisodeConfig, u_max: float) -> Any:
    """``policy``, trained under the episode options ``episode``, as an acceleration policy:
    through :class:`VelocitySetpointPolicy` if it was trained in the velocity mode, else itself.

    Args:
        policy: anything with ``act_batch``.
        episode: the episode options it was trained under.
        u_max: the flown scenario's per-axis input bound [m/s^2].
    """
    if episode.action != "velocity":
        return policy
    return VelocitySetpointPolicy(policy, episode, u_max)
