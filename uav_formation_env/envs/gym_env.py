"""``uav_formation_env/Formation-v0``: a centralised single-agent Gymnasium view of the scenario.

One controller commands every UAV: the action is the N agents' normalised commands concatenated,
``Box(-1, 1, (3 N,))``; the observation is the N agents' observations concatenated,
``(N · dim,)`` float32 (slot table in :mod:`uav_formation_env.core.observation`). The reward is the
mean over agents of the per-agent rewards of the ParallelEnv (minus each UAV's stage cost of J_i,
minus collision penalties), so its scale does not grow with N. Episode end and collision handling
are those of :class:`~uav_formation_env.envs.parallel.UAVFormationParallelEnv`. ``info`` carries the
per-agent ``"J"`` (N,), ``"collision"`` (N,) and ``"t"``.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from uav_formation_env.config import Scenario
from uav_formation_env.envs.parallel import UAVFormationParallelEnv


class FormationGymEnv(gymnasium.Env):
    """Centralised Gymnasium view.

    Args:
        scenario: registered name, YAML path, mapping or Scenario (default: the paper's).
        render_mode: None, "rgb_array" or "human".
        **overrides: single scenario fields, e.g. ``observer__enabled=False``.
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 5}

    def __init__(
        self, scenario: str | Scenario = "paper", render_mode: str | None = None, **overrides: Any
    ) -> None:
        from uav_formation_env.config_io import resolve_with_overrides

        self.parallel = UAVFormationParallelEnv(
            resolve_with_overrides(scenario, overrides), render_mode=render_mode
        )
        self.render_mode = render_mode
        agents = self.parallel.possible_agents
        self._agents = agents
        dim = self.parallel.observation_space(agents[0]).shape[0]
        n = len(agents)
        bound = self.parallel.observation_space(agents[0]).high[0]
        self.observation_space = spaces.Box(-bound, bound, shape=(n * dim,), dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(3 * n,), dtype=np.float32)

    def _flat(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        return np.concatenate([obs[a] for a in self._agents]).astype(np.float32)

    def reset(
        self, *, seed: int | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        obs, _ = self.parallel.reset(seed=seed, options=options)
        return self._flat(obs), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        action = np.asarray(action, dtype=float)
        if action.shape != self.action_space.shape:
            raise ValueError(
                f"action must have shape {self.action_space.shape}, got {action.shape}"
            )
        per_agent = {a: action[3 * i : 3 * i + 3] for i, a in enumerate(self._agents)}
        obs, rewards, terms, truncs, infos = self.parallel.step(per_agent)
        reward = float(self.parallel.episodes.last.team_reward[0])
        info = {
            "J": np.array([infos[a]["J"] for a in self._agents]),
            "collision": np.array([infos[a]["collision"] for a in self._agents]),
            "t": infos[self._agents[0]]["t"],
        }
        first = self._agents[0]
        return self._flat(obs), reward, bool(terms[first]), bool(truncs[first]), info

    def render(self) -> np.ndarray | None:
        return self.parallel.render()

    def close(self) -> None:
        self.parallel.close()
