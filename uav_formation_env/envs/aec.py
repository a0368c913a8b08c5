"""The AEC view: PettingZoo's ``parallel_to_aec`` with each action checked on its own turn.

PettingZoo's converter stores every agent's action and steps the parallel env when the last agent
has acted; a bad action stored earlier then fails that step, and every later one, until reset.
Here an action is checked when its agent submits it: a bad one raises ``ValueError`` naming the
agent and is not stored, so the same agent can act again and the episode goes on. ``step`` before
``reset`` raises ``RuntimeError``; an action other than None for a done agent, ``ValueError``.
"""

from __future__ import annotations

from typing import Any

from pettingzoo.utils.conversions import parallel_to_aec_wrapper

from uav_formation_env.envs.parallel import UAVFormationParallelEnv
from uav_formation_env.episode import validate_action


class UAVFormationAECEnv(parallel_to_aec_wrapper):
    """AEC view of :class:`UAVFormationParallelEnv` (agents act in the order uav_0, uav_1, ...)."""

    def __init__(self, parallel_env: UAVFormationParallelEnv) -> None:
        super().__init__(parallel_env)

    def step(self, action: Any) -> None:
        if not hasattr(self, "agent_selection"):
            raise RuntimeError("call reset() before step()")
        agent = self.agent_selection
        if not (self.terminations[agent] or self.truncations[agent]):
            validate_action(agent, action)  # raises before anything is stored
        elif action is not None:
            raise ValueError(
                f"{agent} is done (terminated or truncated): its action must be None, "
                f"got {action!r}"
            )
        try:
            super().step(action)
        except Exception:
            # the parallel step refused the joint action: forget this turn's action, keep the
            # episode where it was
            self._actions.pop(agent, None)
            raise
