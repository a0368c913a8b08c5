"""Environment views of the scenario: PettingZoo parallel and AEC, Gymnasium, SB3 VecEnv."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pettingzoo.utils import parallel_to_aec

from uav_formation_env.config import Scenario
from uav_formation_env.config_io import resolve_scenario, with_overrides
from uav_formation_env.envs.parallel import UAVFormationParallelEnv


def resolve_with_overrides(
    scenario: str | Path | Scenario | Mapping[str, Any], overrides: Mapping[str, Any]
) -> Scenario:
    """A scenario from a name / YAML path / mapping / object, with validated field overrides."""
    resolved = resolve_scenario(scenario)
    return with_overrides(resolved, overrides) if overrides else resolved


def parallel_env(
    scenario: str | Path | Scenario | Mapping[str, Any] = "paper",
    render_mode: str | None = None,
    **overrides: Any,
) -> UAVFormationParallelEnv:
    """The PettingZoo ParallelEnv ``uav_formation_v0``.

    Args:
        scenario: ``"paper"`` (default), a YAML path, a mapping or a :class:`Scenario`.
        render_mode: None, ``"rgb_array"`` or ``"human"``.
        **overrides: single fields, validated like the scenario: nested mappings
            (``observer={"enabled": False}``) or double-underscore paths
            (``observer__enabled=False``).
    """
    return UAVFormationParallelEnv(resolve_with_overrides(scenario, overrides), render_mode)


def env(
    scenario: str | Path | Scenario | Mapping[str, Any] = "paper",
    render_mode: str | None = None,
    **overrides: Any,
):
    """The AEC view (PettingZoo's ``parallel_to_aec`` of :func:`parallel_env`)."""
    return parallel_to_aec(parallel_env(scenario, render_mode, **overrides))


def vec_env(
    scenario: str | Path | Scenario | Mapping[str, Any] = "paper",
    num_copies: int = 1,
    **overrides: Any,
):
    """A stable-baselines3 VecEnv over ``num_copies`` batched copies, one entry per (copy, agent).

    Imports stable-baselines3 lazily (the ``[rl]`` extra).
    """
    from uav_formation_env.envs.vector import FormationVecEnv

    return FormationVecEnv(resolve_with_overrides(scenario, overrides), num_copies)


__all__ = ["UAVFormationParallelEnv", "env", "parallel_env", "resolve_with_overrides", "vec_env"]
