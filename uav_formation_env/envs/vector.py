"""A stable-baselines3 ``VecEnv`` over B batched scenario copies, one entry per (copy, agent).

For parameter sharing: one policy sees every UAV of every copy as a separate environment entry
(entry ``b * N + i`` is agent ``uav_i`` of copy ``b``), with that agent's observation and reward,
exactly as in :class:`~uav_formation_env.envs.parallel.UAVFormationParallelEnv`. All copies step
together in one :class:`~uav_formation_env.sim.FormationSim` call.

When a copy's episode ends (truncation at the scenario duration, or a collision in ``"terminate"``
mode) all its N entries report ``done``; the copy is reset at once and, as SB3 expects, each entry's
info holds ``"terminal_observation"`` and ``"TimeLimit.truncated"``. Seeding follows SB3: after
``seed(s)`` the next reset seeds copy b with ``s + b`` (so copy b reproduces a ParallelEnv reset
with ``seed=s + b``), and later resets continue each copy's own seed stream.

This module imports stable-baselines3: install the ``[rl]`` extra.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvStepReturn

from uav_formation_env.config import Scenario
from uav_formation_env.envs.gym_vector import per_agent
from uav_formation_env.envs.parallel import UAVFormationParallelEnv
from uav_formation_env.episode import FormationEpisodes
from uav_formation_env.seeding import check_seed


class FormationVecEnv(VecEnv):
    """B batched scenario copies as ``B * N`` SB3 environment entries.

    Args:
        scenario: a validated scenario.
        num_copies: B.
    """

    def __init__(self, scenario: Scenario, num_copies: int = 1) -> None:
        template = UAVFormationParallelEnv(scenario)
        agent = template.possible_agents[0]
        self.scenario = scenario
        self.n_uav = scenario.n_uav
        self.num_copies = int(num_copies)
        self.episodes = FormationEpisodes(scenario, self.num_copies, autoreset=True)
        self.sim = self.episodes.sim
        self.render_mode = None
        super().__init__(
            self.num_copies * self.n_uav,
            template.observation_space(agent),
            template.action_space(agent),
        )
        self._actions: np.ndarray | None = None
        self._copy_seeds: list[int | None] = [None] * self.num_copies

    # ------------------------------------------------------------------ seeding and reset
    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Seed the next reset: copy b gets ``seed + b``. Returns the seed of every entry."""
        seed = check_seed(seed)  # before any change: a refused seed leaves the env as it was
        if seed is None:
            self._copy_seeds = [None] * self.num_copies
        else:
            self._copy_seeds = [seed + b for b in range(self.num_copies)]
        return [s for s in self._copy_seeds for _ in range(self.n_uav)]

    def reset(self) -> np.ndarray:
        step = self.episodes.reset(seed=self._copy_seeds)
        self._copy_seeds = [None] * self.num_copies
        self._reset_seeds()
        self._reset_options()
        return self._flat(step.observation)

    # ------------------------------------------------------------------ stepping
    def step_async(self, actions: np.ndarray) -> None:
        actions = np.asarray(actions)
        if actions.dtype.kind not in "biuf":
            raise ValueError(f"actions must be real numbers, got dtype {actions.dtype}")
        expected = (self.num_envs, 3)
        if actions.shape != expected:
            raise ValueError(f"actions must have shape {expected}, got {actions.shape}")
        if not np.isfinite(actions).all():
            bad = sorted({int(k) for k in np.argwhere(~np.isfinite(actions))[:, 0]})
            raise ValueError(f"actions of entries {bad} contain NaN or infinite values")
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise RuntimeError("step_async() must come before step_wait()")
        actions = self._actions.reshape(self.num_copies, self.n_uav, 3)
        self._actions = None
        step = self.episodes.step(actions)
        observations, rewards, terminated, truncated = per_agent(step)
        infos: list[dict[str, Any]] = [
            {"J": float(j), "collision": bool(c)}
            for j, c in zip(step.cost.ravel(), step.result.collision.ravel())
        ]
        if step.final_observation is not None:
            for b in np.flatnonzero(step.done):
                for i in range(self.n_uav):
                    info = infos[b * self.n_uav + i]
                    info["terminal_observation"] = step.final_observation[b, i].copy()
                    info["TimeLimit.truncated"] = bool(step.truncated[b])
        return observations, rewards.astype(np.float32), terminated | truncated, infos

    def _flat(self, obs: np.ndarray) -> np.ndarray:
        return obs.reshape(self.num_envs, -1)

    # ------------------------------------------------------------------ SB3 plumbing
    def close(self) -> None:
        pass

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        value = getattr(self, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        setattr(self, attr_name, value)

    def env_method(
        self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs
    ) -> list[Any]:
        method = getattr(self, method_name)
        return [method(*method_args, **method_kwargs) for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [None for _ in range(self.num_envs)]
