"""Reinforcement-learning baselines for ``uav_formation_env``: PPO and SAC with one shared policy.

Every UAV of every scenario copy is one entry of a
:class:`~uav_formation_env.envs.vector.FormationVecEnv` (parameter sharing). Hyper-parameters live
in ``baselines/hyperparams/{ppo,sac}.yml`` (rl-baselines3-zoo style, keyed by scenario name with a
``default``); trained runs are evaluated with the package's own runner
(:func:`uav_formation_env.evaluation.run_episodes`), so RL and the reference policies are compared
on the same realised cost.

- :mod:`.train`:
  ``python -m uav_formation_baselines.train --algo ppo --timesteps 200000 --out runs/ppo``
- :mod:`.evaluate`:
  ``python -m uav_formation_baselines.evaluate runs/ppo --seeds 5 --compare heuristic``

The folder ``baselines/`` of the repository installs as the package ``uav_formation_baselines``
(a top-level ``baselines`` would clash with the PyPI project of that name). Importing this package
does not import torch or stable-baselines3; its modules do.
"""

from __future__ import annotations

from pathlib import Path

HYPERPARAMS_DIR = Path(__file__).parent / "hyperparams"
ALGOS = ("ppo", "sac")

__all__ = ["ALGOS", "HYPERPARAMS_DIR"]
