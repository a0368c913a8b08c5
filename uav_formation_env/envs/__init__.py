"""Environment views of the scenario: PettingZoo parallel and AEC, Gymnasium, SB3 VecEnv,
TorchRL EnvBase (torch backend)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from uav_formation_env.config import Scenario
from uav_formation_env.config_io import resolve_with_overrides
from uav_formation_env.envs.aec import UAVFormationAECEnv
from uav_formation_env.envs.parallel import UAVFormationParallelEnv
from uav_formation_env.extras import require
from uav_formation_env.sim_options import SimOptions


def parallel_env(
    scenario: str | Path | Scenario | Mapping[str, Any] = "paper",
    render_mode: str | None = None,
    info_mode: str = "numeric",
    **overrides: Any,
) -> UAVFormationParallelEnv:
    """The PettingZoo ParallelEnv ``uav_formation_v0``.

    Args:
        scenario: ``"paper"`` (default), a YAML path, a mapping or a :class:`Scenario`.
        render_mode: None, ``"rgb_array"`` or ``"human"``.
        info_mode: ``"numeric"`` (numbers and fixed-shape arrays) or ``"rich"`` (see the env).
        **overrides: single fields, validated like the scenario: nested mappings
            (``observer={"enabled": False}``) or double-underscore paths
            (``observer__enabled=False``), e.g. the training devices of the episode layer
            (``episode__reward="log1p"``, ``episode__corridor_width=200.0``); ``reward="train"``
            gives the learnable training task (:mod:`uav_formation_env.tasks`); ``max_cycles=K``
            truncates episodes after K steps (``episode.max_cycles``).
    """
    return UAVFormationParallelEnv(
        resolve_with_overrides(scenario, overrides), render_mode, info_mode
    )


def env(
    scenario: str | Path | Scenario | Mapping[str, Any] = "paper",
    render_mode: str | None = None,
    info_mode: str = "numeric",
    **overrides: Any,
) -> UAVFormationAECEnv:
    """The AEC view of :func:`parallel_env` (PettingZoo's ``parallel_to_aec``, with each action
    checked on its agent's turn: a rejected action leaves the env usable)."""
    return UAVFormationAECEnv(parallel_env(scenario, render_mode, info_mode, **overrides))


def vec_env(
    scenario: str | Path | Scenario | Mapping[str, Any] = "paper",
    num_copies: int = 1,
    **overrides: Any,
):
    """A stable-baselines3 VecEnv over ``num_copies`` batched copies, one entry per (copy, agent).

    Imports stable-baselines3 lazily (the ``[rl]`` extra).

    Args:
        num_copies: B, an integer >= 1.
    """
    if isinstance(num_copies, bool) or not isinstance(num_copies, int | np.integer):
        raise TypeError(f"num_copies must be an integer >= 1, got {num_copies!r}")
    if num_copies < 1:
        raise ValueError(f"num_copies must be an integer >= 1, got {num_copies!r}")
    require("stable_baselines3", "vec_env (a stable-baselines3 VecEnv)")
    from uav_formation_env.envs.vector import FormationVecEnv

    return FormationVecEnv(resolve_with_overrides(scenario, overrides), num_copies)


def torchrl_env(
    scenario: str | Path | Scenario | Mapping[str, Any] = "paper",
    num_envs: int = 1,
    device: Any = "cpu",
    seed: int | None = None,
    return_state: bool = True,
    n_uav: int | None = None,
    compile: bool = False,
    noise: str = "generator",
    **overrides: Any,
):
    """A batched TorchRL ``EnvBase`` of ``num_envs`` copies on the torch backend (CPU or CUDA):
    :class:`~uav_formation_env.envs.torchrl_adapter.FormationTorchRLEnv`.

    Imports torchrl lazily (the ``[torchrl]`` extra).

    Args:
        num_envs: B, an integer >= 1.
        device: torch device of the simulation and of every tensor.
        seed: seed of the first reset.
        return_state: add the global state for centralised critics.
        n_uav: N of a scenario that draws N per reset.
        compile: the whole step through ``torch.compile`` (falls back to the eager step with a
            warning where compilation is not available).
        noise: ``"generator"`` (host blocks) or ``"counter"`` (counter-based draws on the
            device) disturbance noise; see :class:`~uav_formation_env.sim.FormationSim`.
        **overrides: scenario fields, as for :func:`parallel_env`.
    """
    if isinstance(num_envs, bool) or not isinstance(num_envs, int | np.integer) or num_envs < 1:
        raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
    require("torchrl", "torchrl_env (a TorchRL EnvBase)")
    from uav_formation_env.envs.torchrl_adapter import FormationTorchRLEnv

    resolved = resolve_with_overrides(scenario, overrides)
    options = SimOptions(backend="torch", device=device, compile=compile, noise=noise)
    return FormationTorchRLEnv(resolved, int(num_envs), options, seed, return_state, n_uav)


__all__ = [
    "UAVFormationAECEnv",
    "UAVFormationParallelEnv",
    "env",
    "parallel_env",
    "resolve_with_overrides",
    "torchrl_env",
    "vec_env",
]
