"""Gymnasium vector views: the vector entry point and the per-agent view equal their single-copy
and SB3 counterparts step for step, with the same-step autoreset Gymnasium documents."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest

from uav_formation_env import GYM_ID, vec_env
from uav_formation_env.envs.gym_vector import FormationAgentVectorEnv, FormationVectorEnv

OPTIONS = {"episode__corridor_width": 60.0, "duration": 8.0}


def lateral_actions(rng: np.random.Generator, copies: int, agents: int = 5) -> np.ndarray:
    """Random actions, and copy 0 pushed sideways so that it leaves the corridor and resets."""
    actions = rng.uniform(-0.3, 0.3, (copies, agents, 3))
    actions[0, :, 1] = 1.0
    return actions


def test_make_vec_uses_the_vector_entry_point() -> None:
    env = gymnasium.make_vec(GYM_ID, num_envs=3, vectorization_mode="vector_entry_point")
    assert isinstance(env.unwrapped, FormationVectorEnv)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (3, 235) and env.observation_space.contains(obs)
    obs, rewards, terminated, truncated, _ = env.step(env.action_space.sample())
    assert rewards.shape == terminated.shape == truncated.shape == (3,)
    assert np.isfinite(rewards).all()


def test_vector_env_equals_single_envs_with_same_step_autoreset() -> None:
    copies, seed = 3, 10
    vector = FormationVectorEnv(copies, "paper", **OPTIONS)
    singles = [gymnasium.make(GYM_ID, **OPTIONS) for _ in range(copies)]
    obs, _ = vector.reset(seed=seed)
    for b, single in enumerate(singles):
        expected, _ = single.reset(seed=seed + b)
        np.testing.assert_array_equal(obs[b], expected)
    rng = np.random.default_rng(0)
    ended = np.zeros(copies, dtype=bool)
    for _ in range(60):
        actions = lateral_actions(rng, copies).reshape(copies, -1).astype(np.float32)
        obs, rewards, terminated, truncated, infos = vector.step(actions)
        for b, single in enumerate(singles):
            if ended[b]:
                continue
            s_obs, s_reward, s_term, s_trunc, _ = single.step(actions[b])
            assert rewards[b] == pytest.approx(s_reward, rel=1e-12)
            assert (terminated[b], truncated[b]) == (s_term, s_trunc)
            if s_term or s_trunc:
                assert infos["_final_obs"][b]
                np.testing.assert_array_equal(infos["final_obs"][b], s_obs)
                assert obs[b][12] == 0.0  # the next episode already started (t / duration)
                ended[b] = True
            else:
                np.testing.assert_array_equal(obs[b], s_obs)
    assert ended[0]  # copy 0 left the corridor; the others ran into the 8 s limit
    assert ended.all()


def test_agent_vector_env_equals_the_sb3_vec_env() -> None:
    pytest.importorskip("stable_baselines3")
    copies = 2
    agents = FormationAgentVectorEnv(copies, "paper", **OPTIONS)
    sb3 = vec_env("paper", num_copies=copies, **OPTIONS)
    sb3.seed(4)
    np.testing.assert_array_equal(agents.reset(seed=4)[0], sb3.reset())
    rng = np.random.default_rng(1)
    for _ in range(45):
        actions = lateral_actions(rng, copies).reshape(-1, 3)
        obs, rewards, terminated, truncated, infos = agents.step(actions)
        s_obs, s_rewards, s_dones, s_infos = sb3.step(actions)
        np.testing.assert_array_equal(obs, s_obs)
        np.testing.assert_allclose(rewards, s_rewards, rtol=1e-6)  # SB3 rewards are float32
        np.testing.assert_array_equal(terminated | truncated, s_dones)
        for k in np.flatnonzero(s_dones):
            np.testing.assert_array_equal(infos["final_obs"][k], s_infos[k]["terminal_observation"])


def test_vector_views_refuse_bad_input() -> None:
    with pytest.raises(ValueError, match="num_envs must be an integer >= 1"):
        FormationVectorEnv(0)
    env = FormationVectorEnv(2)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(2, 15\)"):
        env.step(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="copy 1, uav_0"):
        bad = np.zeros((2, 15))
        bad[1, 0] = np.nan
        env.step(bad)
    assert env.step(np.zeros((2, 15)))[1].shape == (2,)  # still usable
