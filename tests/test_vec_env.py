"""The stable-baselines3 VecEnv: equal to B separate ParallelEnvs, finite at scale, SB3 plumbing."""

from __future__ import annotations

import time
import warnings

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("torch")

from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.evaluation import evaluate_policy  # noqa: E402
from stable_baselines3.common.monitor import Monitor  # noqa: E402
from stable_baselines3.common.vec_env import VecEnv, VecMonitor, VecNormalize  # noqa: E402

from uav_formation_env import parallel_env, vec_env  # noqa: E402
from uav_formation_env.core.observation import observation_dim  # noqa: E402
from uav_formation_env.scenarios import make_scenario  # noqa: E402

# A 10 m x 10 m start box makes some copies start or drift within collision.uav_distance.
CROWDED = {
    "initial__position_low": (0.0, 0.0, 0.0),
    "initial__position_high": (10.0, 10.0, 0.0),
    "initial__min_spacing": 0.0,
}
CASES = {
    "paper-observer": (make_scenario(duration=4.0), {}),
    "n3-no-observer-random": (
        make_scenario(n_uav=3, observer=False, obstacles="random", duration=4.0),
        {},
    ),
    "penalty-crowded": (make_scenario(collision_mode="penalty", duration=4.0), CROWDED),
    "terminate-crowded": (make_scenario(collision_mode="terminate", duration=4.0), CROWDED),
}


@pytest.mark.parametrize("case", list(CASES))
def test_vec_env_equals_separate_parallel_envs(case):
    scenario, overrides = CASES[case]
    B, seed, steps = 4, 100, 70  # 20-step episodes: at least three auto-resets per copy
    venv = vec_env(scenario, num_copies=B, **overrides)
    n = venv.n_uav
    assert isinstance(venv, VecEnv)
    assert venv.num_envs == B * n
    assert venv.observation_space.shape == (observation_dim(n),)
    assert venv.action_space.shape == (3,)
    singles = [parallel_env(scenario, **overrides) for _ in range(B)]
    agents = singles[0].possible_agents

    seeds = venv.seed(seed)
    assert list(seeds) == [seed + b for b in range(B) for _ in range(n)]
    obs = venv.reset()
    assert obs.shape == (B * n, observation_dim(n)) and obs.dtype == np.float32
    for b, single in enumerate(singles):
        par_obs, _ = single.reset(seed=seed + b)
        for i, agent in enumerate(agents):
            assert np.array_equal(obs[b * n + i], par_obs[agent])

    rng = np.random.default_rng(seed)
    episodes_ended = np.zeros(B, dtype=int)
    terminated_seen = truncated_seen = collided_seen = False
    for _ in range(steps):
        actions = rng.uniform(-1.2, 1.2, size=(B * n, 3)).astype(np.float32)
        obs, rewards, dones, infos = venv.step(actions)
        assert obs.dtype == np.float32 and rewards.dtype == np.float32 and dones.dtype == bool
        assert len(infos) == B * n
        for b, single in enumerate(singles):
            par_obs, par_rew, terms, truncs, par_infos = single.step(
                {agent: actions[b * n + i] for i, agent in enumerate(agents)}
            )
            done = not single.agents
            assert done == (any(terms.values()) or any(truncs.values()))
            if done:
                episodes_ended[b] += 1
                terminated_seen |= any(terms.values())
                truncated_seen |= any(truncs.values())
                next_obs, _ = single.reset()  # continues the copy's seed stream
            for i, agent in enumerate(agents):
                k = b * n + i
                assert rewards[k] == np.float32(par_rew[agent])
                assert infos[k]["J"] == par_infos[agent]["J"]
                assert infos[k]["collision"] == par_infos[agent]["collision"]
                collided_seen |= infos[k]["collision"]
                assert dones[k] == done
                if done:
                    assert np.array_equal(infos[k]["terminal_observation"], par_obs[agent])
                    assert infos[k]["TimeLimit.truncated"] == bool(truncs[agent])
                    assert np.array_equal(obs[k], next_obs[agent])
                else:
                    assert "terminal_observation" not in infos[k]
                    assert np.array_equal(obs[k], par_obs[agent])
    assert (episodes_ended >= 3).all()
    if case.endswith("crowded"):
        assert collided_seen
    if case == "terminate-crowded":
        assert terminated_seen
    else:
        assert truncated_seen and not terminated_seen


def test_seed_reproduces_and_differs():
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, size=(30, 2 * 5, 3))
    runs = []
    for seed in (3, 3, 4):
        venv = vec_env(make_scenario(duration=2.0), num_copies=2)
        venv.seed(seed)
        trace = [venv.reset()]
        for a in actions:
            trace.append(venv.step(a)[0])
        runs.append(np.stack(trace))
    assert np.array_equal(runs[0], runs[1])
    assert not np.array_equal(runs[0], runs[2])
    # copy 1 of seed 3 starts as copy 0 of seed 4
    assert np.array_equal(runs[0][0, 5:], runs[2][0, :5])


def test_million_agent_steps_are_finite(record_property):
    B, steps = 200, 1000  # 200 copies x 5 agents x 1000 steps = 10^6 agent-steps
    venv = vec_env("paper", num_copies=B)
    assert venv.scenario.observer.enabled
    venv.seed(0)
    obs = venv.reset()
    rng = np.random.default_rng(0)
    start = time.perf_counter()
    dones_total = 0
    for _ in range(steps):
        actions = rng.uniform(-1.0, 1.0, size=(venv.num_envs, 3))
        obs, rewards, dones, infos = venv.step(actions)
        assert np.isfinite(obs).all()
        assert np.isfinite(rewards).all()
        j = np.fromiter((info["J"] for info in infos), float, count=len(infos))
        assert np.isfinite(j).all()
        dones_total += int(dones.sum())
        for k in np.flatnonzero(dones):
            assert np.isfinite(infos[k]["terminal_observation"]).all()
    elapsed = time.perf_counter() - start
    assert dones_total == venv.num_envs  # every copy truncates once, at step 1000
    record_property("agent_steps_per_s", B * 5 * steps / elapsed)
    print(f"10^6 agent-steps in {elapsed:.1f} s")


BAD_ACTIONS = {
    "flat": lambda n: np.zeros(n),
    "two columns": lambda n: np.zeros((n, 2)),
    "one entry short": lambda n: np.zeros((n - 1, 3)),
    "per copy": lambda n: np.zeros((n // 5, 5, 3)),
    "NaN": lambda n: np.where(np.arange(n * 3).reshape(n, 3) == 7, np.nan, 0.0),
    "inf": lambda n: np.where(np.arange(n * 3).reshape(n, 3) == 4, -np.inf, 0.0),
}


@pytest.mark.parametrize("case", list(BAD_ACTIONS))
def test_bad_actions_raise_and_env_keeps_working(case):
    venv = vec_env(num_copies=2)
    venv.seed(0)
    venv.reset()
    reference = vec_env(num_copies=2)
    reference.seed(0)
    reference.reset()
    with pytest.raises(ValueError, match="shape|NaN"):
        venv.step(BAD_ACTIONS[case](venv.num_envs))
    assert (venv.sim.steps == 0).all()
    good = np.random.default_rng(0).uniform(-1, 1, size=(venv.num_envs, 3))
    obs, rewards, _, _ = venv.step(good)
    ref_obs, ref_rewards, _, _ = reference.step(good)
    assert np.array_equal(obs, ref_obs) and np.array_equal(rewards, ref_rewards)


def test_nan_error_names_the_entry():
    venv = vec_env(num_copies=2)
    venv.reset()
    actions = np.zeros((venv.num_envs, 3))
    actions[7, 1] = np.nan
    with pytest.raises(ValueError, match=r"\[7\]"):
        venv.step(actions)
    with pytest.raises(RuntimeError):
        venv.step_wait()  # no pending step_async


def test_out_of_range_actions_are_clipped():
    venvs = [vec_env(num_copies=2) for _ in range(2)]
    for v in venvs:
        v.seed(1)
        v.reset()
    signs = np.random.default_rng(1).choice([-1.0, 1.0], size=(10, 3))
    big = venvs[0].step(7.5 * signs)
    unit = venvs[1].step(signs)
    assert np.array_equal(big[0], unit[0]) and np.array_equal(big[1], unit[1])


def test_sb3_plumbing():
    venv = vec_env(make_scenario(n_uav=3, duration=2.0), num_copies=2)
    assert venv.num_envs == 6
    assert venv.get_attr("render_mode") == [None] * 6
    assert venv.get_attr("n_uav", indices=[0, 4]) == [3, 3]
    assert venv.get_attr("scenario", indices=2) == [venv.scenario]
    assert venv.env_is_wrapped(Monitor) == [False] * 6
    assert venv.env_is_wrapped(Monitor, indices=[1, 2]) == [False, False]
    seeds = venv.env_method("seed", 5, indices=[0])
    assert len(seeds) == 1 and list(seeds[0]) == [5, 5, 5, 6, 6, 6]
    venv.set_attr("custom_flag", 1)
    assert venv.get_attr("custom_flag") == [1] * 6
    assert len(venv.get_images()) == 6
    venv.reset()
    venv.close()

    # evaluate_policy through VecMonitor: one 10-step episode per entry
    model = PPO("MlpPolicy", venv, n_steps=8, batch_size=16, n_epochs=1, seed=0, device="cpu")
    monitored = VecMonitor(vec_env(make_scenario(n_uav=3, duration=2.0), num_copies=2))
    mean, std = evaluate_policy(model, monitored, n_eval_episodes=6)
    assert np.isfinite(mean) and np.isfinite(std) and mean < 0.0


def _ppo(venv):
    return PPO(
        "MlpPolicy",
        venv,
        n_steps=16,
        batch_size=64,
        n_epochs=1,
        policy_kwargs={"net_arch": [32, 32]},
        seed=0,
        device="cpu",
    )


def test_ppo_learns_and_vecnormalize_wraps():
    scenario = make_scenario(duration=2.0)
    params = []
    for _ in range(2):
        model = _ppo(vec_env(scenario, num_copies=4))  # 20 entries x 16 steps = one rollout
        model.learn(256)
        assert model.num_timesteps >= 256
        params.append(
            np.concatenate([p.detach().numpy().ravel() for p in model.policy.parameters()])
        )
    assert np.isfinite(params[0]).all()
    assert np.array_equal(params[0], params[1]), "PPO with seed=0 is not reproducible"

    normalized = VecNormalize(vec_env(scenario, num_copies=4), norm_obs=True, norm_reward=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = _ppo(normalized)
        model.learn(256)
    assert model.num_timesteps >= 256
    assert normalized.obs_rms.count > 1
    obs = normalized.reset()
    assert obs.shape == (20, observation_dim(5)) and np.isfinite(obs).all()
