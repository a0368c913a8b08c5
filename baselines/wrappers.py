"""The SB3 training stack: the episode layer's training devices, then VecMonitor and VecNormalize.

Every episode rule lives in :mod:`uav_formation_env.episode`; training only sets its options
(``training["episode"]``, merged into ``scenario.episode``), measured with PPO on the paper's
scenario:

- divergence truncation (``max_formation_error`` 100 m, ``max_velocity_error`` 40 m/s): without
  it learning *diverges* (the evaluated cost per UAV grows from 1.6e8 untrained to 1e10-3e11 after
  300k agent-steps, whatever the reward transform), with it the cost falls to 2e7 after 300k and
  7.5e5 after 3M (heuristic: 4.9e5 on the same seeds);
- ``start="staggered"``: all copies share one episode clock, so without it every rollout sees one
  phase of the 1000-step mission for all copies at once; the first reset spreads copy b to step
  b T / B of an episode flown by the consensus-PD controller;
- the reward transform (``reward`` ``"log1p"`` or ``"scaled"``); ``"raw"`` with VecNormalize did
  best in our runs. Evaluation always reports the untransformed cost.

``VecMonitor`` therefore logs the returns of the transformed reward; the raw stage cost is in
every entry's info (``"J"``).
"""

from __future__ import annotations

from typing import Any

from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

from uav_formation_env.config import Scenario
from uav_formation_env.config_io import with_overrides
from uav_formation_env.envs.vector import FormationVecEnv


def training_scenario(scenario: Scenario, training: dict[str, Any]) -> Scenario:
    """``scenario`` with the training-only overrides and the episode layer's training options
    (``training["env_overrides"]`` and ``training["episode"]``)."""
    overrides = dict(training.get("env_overrides") or {})
    episode = training.get("episode") or {}
    if episode:
        overrides["episode"] = {**overrides.get("episode", {}), **episode}
    return with_overrides(scenario, overrides) if overrides else scenario


def make_training_env(
    scenario: Scenario, training: dict[str, Any], gamma: float
) -> tuple[VecNormalize, FormationVecEnv]:
    """The training stack of the module docstring and its innermost FormationVecEnv.

    Args:
        scenario: the scenario as evaluated (the training options are applied on top).
        training: training set-up keys
            (see :data:`uav_formation_baselines.config.TRAINING_DEFAULTS`).
        gamma: discount of the algorithm, for VecNormalize's return statistics.
    """
    base = FormationVecEnv(training_scenario(scenario, training), int(training["copies"]))
    normalize = dict(training.get("normalize") or {})
    normalize.setdefault("gamma", gamma)
    return VecNormalize(VecMonitor(base), **normalize), base
