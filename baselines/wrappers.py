"""The training VecEnv stack: FormationVecEnv -> divergence reset -> staggered start -> VecMonitor
-> reward transform -> VecNormalize.

- :class:`DivergenceReset`: a copy flown far off course (formation or velocity error beyond a
  bound no useful policy reaches) is restarted, as a time-limit truncation. Measured with PPO on
  the paper's scenario: without it learning *diverges* (the evaluated cost per UAV grows from
  1.6e8 untrained to 1e10-3e11 after 300k agent-steps, whatever the reward transform), with it
  the cost falls to 2e7 after 300k and 7.5e5 after 3M (heuristic: 4.9e5 on the same seeds).
- :class:`StaggeredReset`: all B copies of a :class:`FormationVecEnv` share one episode clock, so
  without it every rollout sees one phase of the 1000-step mission (e.g. only the first leg and
  obstacle) for all copies at once. At the first reset, copy b is advanced to step ``b T / B`` of
  an episode flown by the heuristic controller, so that the copies cover the whole mission and
  stay spread (every full episode has the same length T; divergence resets reshuffle phases).
- ``VecMonitor`` sits below the reward transform so that ``rollout/ep_rew_mean`` in the logs is
  the episode's true return, minus the realised cost of one UAV (of possibly cut episodes).
- :class:`RewardTransform`: optional ``"log"`` / ``"sqrt"`` compression of the stage cost J, which
  ranges over eight decades. Both did worse than the plain ``-J`` with VecNormalize in our runs
  (default ``"none"``); evaluation always reports the untransformed cost.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper, VecMonitor, VecNormalize
from stable_baselines3.common.vec_env.base_vec_env import VecEnvStepReturn

from uav_formation_env.config import Scenario
from uav_formation_env.config_io import with_overrides
from uav_formation_env.core.cost import anchored
from uav_formation_env.envs.vector import FormationVecEnv
from uav_formation_env.episode import observations_of
from uav_formation_env.evaluation import HeuristicPolicy

REWARD_TRANSFORMS = ("none", "log", "sqrt")


def _formation_vec_env(venv: VecEnv, wrapper: str) -> FormationVecEnv:
    """The FormationVecEnv at the bottom of ``venv``, whose sim a wrapper acts on."""
    base = venv.unwrapped
    if not isinstance(base, FormationVecEnv):
        raise TypeError(f"{wrapper} needs a FormationVecEnv underneath, got {type(base).__name__}")
    return base


class RewardTransform(VecEnvWrapper):
    """Reward ``-J`` to ``-log(1 + J / scale)`` (``"log"``), ``-sqrt(J / scale)`` (``"sqrt"``,
    an error norm rather than its square) or unchanged (``"none"``).

    Args:
        venv: the wrapped VecEnv (rewards are minus non-negative costs).
        kind: one of :data:`REWARD_TRANSFORMS`.
        scale: J0 [-], the cost below which the transform is nearly linear.
    """

    def __init__(self, venv: VecEnv, kind: str = "log", scale: float = 100.0) -> None:
        if kind not in REWARD_TRANSFORMS:
            raise ValueError(f"reward_transform must be one of {REWARD_TRANSFORMS}, got {kind!r}")
        if not scale > 0:
            raise ValueError(f"reward_scale must be > 0, got {scale!r}")
        super().__init__(venv)
        self.kind = kind
        self.scale = float(scale)

    def reset(self) -> np.ndarray:
        return self.venv.reset()

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, dones, infos = self.venv.step_wait()
        if self.kind != "none":
            cost = np.maximum(-np.asarray(rewards, dtype=np.float64), 0.0) / self.scale
            shaped = np.log1p(cost) if self.kind == "log" else np.sqrt(cost)
            rewards = (-shaped).astype(np.float32)
        return obs, rewards, dones, infos


class StaggeredReset(VecEnvWrapper):
    """Spread the copies' episode phases at the first reset (see the module docstring).

    Args:
        venv: a :class:`FormationVecEnv`, possibly wrapped (its ``sim`` is advanced directly).
    """

    def __init__(self, venv: FormationVecEnv) -> None:
        self.base = _formation_vec_env(venv, "StaggeredReset")
        super().__init__(venv)
        self._staggered = False

    def reset(self) -> np.ndarray:
        obs = self.venv.reset()
        if self._staggered:
            return obs
        self._staggered = True
        base = self.base
        return self._advance(base, obs.reshape(base.num_copies, base.n_uav, -1))

    @staticmethod
    def _advance(base: FormationVecEnv, obs: np.ndarray) -> np.ndarray:
        copies, n_steps = base.num_copies, base.scenario.n_steps
        offsets = (np.arange(copies) * n_steps) // copies  # steps copy b is into its episode
        start = offsets.max() - offsets  # warm-up step at which copy b restarts
        policy = HeuristicPolicy(base.scenario)
        sim, u_max = base.sim, base.scenario.dynamics.u_max
        for k in range(int(offsets.max()) + 1):
            restart = start == k
            if restart.any():
                result = sim.reset(seed=None, mask=restart)
                obs = np.where(restart[:, None, None], observations_of(sim, result), obs)
            if k == offsets.max():
                break
            result = sim.step(np.clip(policy.act_batch(obs), -1.0, 1.0) * u_max)
            obs = observations_of(sim, result)
        return obs.reshape(base.num_envs, -1)

    def step_wait(self) -> VecEnvStepReturn:
        return self.venv.step_wait()


class DivergenceReset(VecEnvWrapper):
    """End a copy's episode early once it has flown far off course, and restart it.

    A copy whose UAVs stray more than ``max_spread`` metres from their formation slots (anchored
    at the swarm's mean) or more than ``max_velocity_error`` m/s from their reference velocity is
    reset, reported as a time-limit truncation (``TimeLimit.truncated``), so the learner
    bootstraps from the value there: no incentive to diverge or to avoid it, only no more samples
    from states no useful policy visits. Without it, the drift of a poor early policy compounds
    over the 1000-step episodes into costs eight decades above the heuristic's, and those samples
    swamp the learning signal (PPO then diverges on the paper's scenario, not on 200-step
    episodes). As the policy improves, episodes run longer: an automatic curriculum.

    Args:
        venv: a :class:`FormationVecEnv`, possibly wrapped (its ``sim`` is read and reset by
            copy).
        max_spread: formation-error bound [m] (the heuristic stays below about 60 m).
        max_velocity_error: velocity-error bound [m/s] (a 90 degree turn of the preset velocity
            at 20 m/s is a 28 m/s error).
    """

    def __init__(
        self, venv: VecEnv, max_spread: float = 100.0, max_velocity_error: float = 40.0
    ) -> None:
        self.base = _formation_vec_env(venv, "DivergenceReset")
        super().__init__(venv)
        self.max_spread = float(max_spread)
        self.max_velocity_error = float(max_velocity_error)
        self.resets = 0

    def reset(self) -> np.ndarray:
        return self.venv.reset()

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, dones, infos = self.venv.step_wait()
        base = self.base
        n, sim = base.n_uav, base.sim
        diverged = self.diverged(base) & ~dones.reshape(-1, n).any(axis=1)
        if diverged.any():
            self.resets += int(diverged.sum())
            for b in np.flatnonzero(diverged):
                for k in range(b * n, (b + 1) * n):
                    infos[k]["terminal_observation"] = obs[k].copy()
                    infos[k]["TimeLimit.truncated"] = True
                    dones[k] = True
            fresh = observations_of(sim, sim.reset(seed=None, mask=diverged))
            obs = np.where(np.repeat(diverged, n)[:, None], fresh.reshape(base.num_envs, -1), obs)
        return obs, rewards, dones, infos

    def diverged(self, base: FormationVecEnv) -> np.ndarray:
        """(B,) whether each copy is beyond a bound now."""
        last = base.sim.last
        formation = base.scenario.formation
        a = anchored(last.z, np.asarray(formation.offsets, float), formation.mirrored_offsets)
        spread = np.linalg.norm(a[..., :3] - a[..., :3].mean(axis=1, keepdims=True), axis=-1)
        v_error = np.linalg.norm(last.z[..., 3:] - last.reference_velocity, axis=-1)
        return (spread.max(axis=1) > self.max_spread) | (
            v_error.max(axis=1) > self.max_velocity_error
        )


def make_training_env(
    scenario: Scenario, training: dict[str, Any], gamma: float
) -> tuple[VecNormalize, FormationVecEnv]:
    """The training stack of the module docstring and its innermost FormationVecEnv.

    Args:
        scenario: the scenario (``training["env_overrides"]`` are applied on top).
        training: training set-up keys
            (see :data:`uav_formation_baselines.config.TRAINING_DEFAULTS`).
        gamma: discount of the algorithm, for VecNormalize's return statistics.
    """
    overrides = training.get("env_overrides") or {}
    if overrides:
        scenario = with_overrides(scenario, overrides)
    base = FormationVecEnv(scenario, int(training["copies"]))
    env: VecEnv = base
    bounds = training.get("divergence_reset")
    if bounds:
        env = DivergenceReset(env, **bounds)
    if training.get("stagger_start", True):
        env = StaggeredReset(env)
    env = VecMonitor(env)
    env = RewardTransform(env, training.get("reward_transform", "log"), training["reward_scale"])
    normalize = dict(training.get("normalize") or {})
    normalize.setdefault("gamma", gamma)
    return VecNormalize(env, **normalize), base
