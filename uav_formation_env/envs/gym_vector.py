"""Gymnasium vector views of B batched copies, both thin views of the episode layer.

- :class:`FormationVectorEnv`: the vector entry point of ``uav_formation_env/Formation-v0``
  (``gymnasium.make_vec(GYM_ID, num_envs=B, vectorization_mode="vector_entry_point")``): one entry
  per copy, the centralised view of :class:`~uav_formation_env.envs.gym_env.FormationGymEnv`
  (observation: the N agents' observations concatenated; action: their N commands concatenated;
  reward: the mean over agents of the per-agent rewards).
- :class:`FormationAgentVectorEnv`: one entry per (copy, agent), entry ``b N + i`` being agent
  ``uav_i`` of copy b, for parameter sharing in CleanRL-style loops (the layout of the SB3
  VecEnv, :mod:`uav_formation_env.envs.vector`, which shares :func:`per_agent`).

Both reset a copy as soon as its episode ends, in the same step (Gymnasium's ``SAME_STEP``
autoreset): ``infos["final_obs"]`` holds the last observation of the entries that ended
(``infos["_final_obs"]`` marks them) and ``infos["final_info"]`` their infos.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from uav_formation_env.config import Scenario
from uav_formation_env.core.local_observation import observation_size
from uav_formation_env.core.observation import OBSERVATION_BOUND
from uav_formation_env.episode import EpisodeStep, FormationEpisodes

ScenarioLike = str | Path | Scenario | Mapping[str, Any]


def per_agent(step: EpisodeStep) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A step as one row per (copy, agent): observations (B N, dim), rewards (B N,),
    terminations and truncations (B N,) (every agent of a copy ends with it)."""
    batch, n = step.reward.shape
    observations = step.observation.reshape(batch * n, -1)
    return (
        observations,
        step.reward.reshape(-1),
        np.repeat(step.terminated, n),
        np.repeat(step.truncated, n),
    )


class _BatchedView(gymnasium.vector.VectorEnv):
    """What both vector views share: the layer, seeding, SAME_STEP autoreset bookkeeping."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(self, copies: int, scenario: ScenarioLike, overrides: Mapping[str, Any]) -> None:
        from uav_formation_env.config_io import resolve_with_overrides

        if isinstance(copies, bool) or not isinstance(copies, int | np.integer) or copies < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {copies!r}")
        overrides = {k: v for k, v in overrides.items() if k != "max_episode_steps"}
        self.scenario = resolve_with_overrides(scenario, overrides)
        self.episodes = FormationEpisodes(self.scenario, int(copies), autoreset=True)
        self.n_uav = self.scenario.n_uav
        self.obs_dim = observation_size(self.scenario)

    def _spaces(self, entries: int, obs_size: int, act_size: int) -> None:
        """Single and batched spaces of ``entries`` rows of ``obs_size`` / ``act_size`` values."""
        self.num_envs = entries
        bound = OBSERVATION_BOUND
        self.single_observation_space = spaces.Box(-bound, bound, (obs_size,), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (act_size,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, entries)
        self.action_space = batch_space(self.single_action_space, entries)

    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        # an int seeds copy b with seed + b (Gymnasium's and SB3's convention)
        step = self.episodes.reset(seed=seed)
        return step.observation.reshape(self.num_envs, -1), {}

    def _infos(self, step: EpisodeStep, rows: int) -> dict[str, Any]:
        """Per-entry arrays: the raw stage cost ``J`` and the ``collision`` flags."""
        batch = step.reward.shape[0]
        cost, collision = step.cost, step.result.collision
        if rows != batch:  # one row per agent
            return {"J": cost.reshape(-1), "collision": collision.reshape(-1)}
        return {"J": cost, "collision": collision}

    @staticmethod
    def _final(infos: dict[str, Any], done: np.ndarray, final_obs: np.ndarray) -> None:
        if not done.any():
            return
        obs = np.empty(len(done), dtype=object)
        final_info = np.empty(len(done), dtype=object)
        for k in np.flatnonzero(done):  # only the entries that ended, once per episode
            obs[k] = final_obs[k]
            final_info[k] = {"J": infos["J"][k], "collision": infos["collision"][k]}
        infos.update(final_obs=obs, _final_obs=done, final_info=final_info, _final_info=done)


class FormationVectorEnv(_BatchedView):
    """B copies, one centralised entry each (see the module docstring).

    Args:
        num_envs: B.
        scenario: registered name, YAML path, mapping or Scenario.
        render_mode: only None (batched rendering is not offered).
        **overrides: scenario fields, e.g. ``episode__reward="log1p"``.
    """

    def __init__(
        self,
        num_envs: int = 1,
        scenario: ScenarioLike = "paper",
        render_mode: str | None = None,
        **overrides: Any,
    ) -> None:
        if render_mode is not None:
            raise ValueError(f"render_mode must be None for the vector view, got {render_mode!r}")
        super().__init__(num_envs, scenario, overrides)
        self._spaces(int(num_envs), self.n_uav * self.obs_dim, 3 * self.n_uav)

    def step(self, actions: np.ndarray):
        actions = np.asarray(actions)
        expected = (self.num_envs, 3 * self.n_uav)
        if actions.shape != expected:
            raise ValueError(f"actions must have shape {expected}, got {actions.shape}")
        step = self.episodes.step(actions.reshape(self.num_envs, self.n_uav, 3))
        infos = self._infos(step, self.num_envs)
        if step.final_observation is not None:
            self._final(infos, step.done, step.final_observation.reshape(self.num_envs, -1))
        return (
            step.observation.reshape(self.num_envs, -1),
            step.team_reward,
            step.terminated.copy(),
            step.truncated.copy(),
            infos,
        )


class FormationAgentVectorEnv(_BatchedView):
    """B copies as B N entries, one per (copy, agent), for parameter sharing.

    Args:
        num_copies: B (``num_envs`` is B N).
        scenario: registered name, YAML path, mapping or Scenario.
        **overrides: scenario fields.
    """

    def __init__(self, num_copies: int = 1, scenario: ScenarioLike = "paper", **overrides: Any):
        super().__init__(num_copies, scenario, overrides)
        self.num_copies = int(num_copies)
        self._spaces(self.num_copies * self.n_uav, self.obs_dim, 3)

    def step(self, actions: np.ndarray):
        actions = np.asarray(actions)
        if actions.shape != (self.num_envs, 3):
            raise ValueError(f"actions must have shape {(self.num_envs, 3)}, got {actions.shape}")
        step = self.episodes.step(actions.reshape(self.num_copies, self.n_uav, 3))
        observations, rewards, terminated, truncated = per_agent(step)
        infos = self._infos(step, self.num_envs)
        if step.final_observation is not None:
            final = step.final_observation.reshape(self.num_envs, -1)
            self._final(infos, terminated | truncated, final)
        return observations, rewards, terminated, truncated, infos
