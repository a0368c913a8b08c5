"""Trainers use the environment unpatched: TorchRL's PettingZoo wrapper passes its own checker."""

from __future__ import annotations

import numpy as np
import pytest

from uav_formation_env import parallel_env

torchrl_pettingzoo = pytest.importorskip(
    "torchrl.envs.libs.pettingzoo", reason="the [torchrl] extra is not installed"
)


def test_torchrl_pettingzoo_wrapper_passes_check_env_specs() -> None:
    from torchrl.envs.utils import check_env_specs

    env = torchrl_pettingzoo.PettingZooWrapper(env=parallel_env("paper"))
    check_env_specs(env)
    rollout = env.rollout(10)
    group = rollout["uav"]  # one group, named after the agents' prefix: the 5 UAVs
    assert group["observation"].shape == (10, 5, 47)
    info = rollout["next", "uav", "info"]
    assert info["neighbours"].shape == (10, 5, 5)
    reward = rollout["next", "uav", "reward"]
    np.testing.assert_allclose(reward[..., 0].numpy(), -info["J"].numpy(), rtol=1e-6)


def test_torchrl_sees_the_training_devices() -> None:
    env = torchrl_pettingzoo.PettingZooWrapper(
        env=parallel_env("paper", episode__reward="log1p", episode__reward_scale=100.0)
    )
    rollout = env.rollout(5)
    reward = rollout["next", "uav", "reward"][..., 0].numpy()
    cost = rollout["next", "uav", "info", "J"].numpy()
    np.testing.assert_allclose(reward, -np.log1p(cost / 100.0), rtol=1e-5)
    assert np.abs(reward).max() < 20.0  # a few units, not the raw 1e2..1e8
