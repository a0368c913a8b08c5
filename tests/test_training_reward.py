"""The training task: the bounded reward's closed forms, the velocity action mode, the route slots,
the task ladder and the training preset through every view."""

from __future__ import annotations

from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

import uav_formation_env
from uav_formation_env import parallel_env
from uav_formation_env.config import CostConfig, Scenario, TrainingRewardConfig
from uav_formation_env.config_io import with_overrides
from uav_formation_env.core.cost import CostTerms
from uav_formation_env.core.dynamics import velocity_setpoint_input
from uav_formation_env.core.reference import slot_route_offset
from uav_formation_env.core.training_reward import TERMS, reward_terms, training_reward
from uav_formation_env.episode import FormationEpisodes
from uav_formation_env.policies.action_modes import VelocitySetpointPolicy
from uav_formation_env.tasks import LADDER, evaluation_scenario, training_scenario


def _terms(**values: float) -> CostTerms:
    names = ("formation", "energy", "terminal", "velocity", "separation", "obstacle")
    return CostTerms(**{n: np.full((1, 1), values.get(n, 0.0)) for n in names})


def test_kernels_match_hand_computed_values():
    config, weights = TrainingRewardConfig(), CostConfig()  # q 1, r 5, n 10, s 30
    # |v - v^d| = σ_v, Σ|ε|² = 3 σ_f² over 3 neighbours, |u| = 0, no close pair, route error
    # 2 σ_r, c - σ_c from the surface
    cost = _terms(
        velocity=weights.n * config.velocity_scale**2,
        formation=weights.q * 3 * config.formation_scale**2,
    )
    route = np.full((1, 1), 2 * config.route_scale)
    surface = np.full((1, 1), config.clearance_margin - config.clearance_scale)
    terms = reward_terms(config, weights, cost, route, surface, np.full((1, 1), 3.0))
    assert set(terms) == set(TERMS)
    expected = {
        "velocity": config.velocity / 2,
        "formation": config.formation / 2,
        "route": config.route / 5,
        "energy": config.energy,
        "separation": config.separation,
        "clearance": config.clearance / 2,
    }
    for name, value in expected.items():
        assert terms[name][0, 0] == pytest.approx(value, rel=1e-12), name


def test_perfect_step_pays_the_weights_and_termination_costs_the_penalty():
    config, weights = TrainingRewardConfig(), CostConfig()
    zero = np.zeros((2, 3))
    terms = reward_terms(config, weights, _terms(), zero, np.full((2, 3), np.inf), zero)
    reward = training_reward(terms, np.array([False, True]), config.termination_penalty)
    total = sum(getattr(config, name) for name in TERMS)
    np.testing.assert_allclose(reward[0], total)
    np.testing.assert_allclose(reward[1], total - config.termination_penalty)


def test_a_term_whose_weight_is_zero_is_absent():
    weights = replace(CostConfig(), separation=0.0)
    terms = reward_terms(
        TrainingRewardConfig(),
        weights,
        _terms(separation=5.0),
        np.zeros((1, 1)),
        np.zeros((1, 1)),
        np.ones((1, 1)),
    )
    assert terms["separation"][0, 0] == TrainingRewardConfig().separation


def test_velocity_setpoint_input_closed_form():
    v = np.array([[20.0, 0.0, 0.0]])
    ref = np.array([[20.0, 1.0, 0.0]])
    a = np.array([[0.0, 0.0, 0.1]])
    u = velocity_setpoint_input(a, v, ref, velocity_range=10.0, gain=2.0, u_max=5.0)
    np.testing.assert_allclose(u, [[0.0, 2.0, 2.0]])
    u = velocity_setpoint_input(np.ones((1, 3)), v, ref, 10.0, 2.0, 5.0)
    np.testing.assert_allclose(u, [[5.0, 5.0, 5.0]])  # clipped at u_max


def test_slot_route_offset_shows_a_displaced_uav_alone():
    scenario = Scenario()
    offsets = np.asarray(scenario.formation.offsets)[:, :3]
    centre = np.array([100.0, 50.0, 0.0])
    positions = (offsets + centre)[None]
    start = positions.mean(axis=1)
    t = np.zeros(1)
    anchored = positions - offsets
    zero = slot_route_offset(scenario.schedule, t, positions, anchored, start)
    np.testing.assert_allclose(zero, 0.0, atol=1e-12)
    moved = positions.copy()
    moved[0, 2] += (3.0, 4.0, 0.0)
    offset = slot_route_offset(scenario.schedule, t, moved, moved - offsets, start)
    np.testing.assert_allclose(offset[0, 2], (3.0, 4.0), atol=1e-12)
    np.testing.assert_allclose(np.delete(offset[0], 2, axis=0), 0.0, atol=1e-12)


@pytest.mark.parametrize("name", [n for n in LADDER if n != "random_swarm"])  # one N per sim
def test_training_task_rewards_are_bounded_sums_of_terms(name):
    scenario = training_scenario(name)
    episodes = FormationEpisodes(scenario, batch_size=3, autoreset=True)
    step = episodes.reset(seed=0)
    rng = np.random.default_rng(0)
    total = sum(getattr(scenario.episode.train, t) for t in TERMS)
    for _ in range(30):
        step = episodes.step(rng.uniform(-1, 1, (3, episodes.n_uav, 3)))
        summed = sum(step.terms.values())
        penalty = scenario.episode.train.termination_penalty * step.terminated[:, None]
        np.testing.assert_allclose(step.reward, summed - penalty)
        assert (summed > 0).all() and (summed <= total + 1e-12).all()
    assert step.observation.shape[-1] == episodes.observe().shape[-1]


def test_velocity_mode_with_zero_action_tracks_the_reference():
    scenario = with_overrides(
        training_scenario("hold"), {"observer__enabled": False, "disturbance__model": "none"}
    )
    episodes = FormationEpisodes(scenario, batch_size=2)
    episodes.reset(seed=3)
    for _ in range(50):
        step = episodes.step(np.zeros((2, 5, 3)))
    error = step.result.z[..., 3:] - step.result.reference_velocity
    assert np.abs(error).max() < 1e-3  # P loop, gain 1 / s: e^-10 of the initial error after 10 s


def test_velocity_policy_adapter_equals_the_episode_layers_inner_loop():
    train = training_scenario("track")
    episodes = FormationEpisodes(train, batch_size=2)
    step = episodes.reset(seed=1)
    for _ in range(5):
        step = episodes.step(np.full((2, 5, 3), 0.3))
    setpoint = np.random.default_rng(1).uniform(-1, 1, (2, 5, 3))

    class Constant:
        def act_batch(self, obs):
            return setpoint

    adapter = VelocitySetpointPolicy(Constant(), train.episode, train.dynamics.u_max)
    expected = episodes._input(setpoint) / train.dynamics.u_max
    np.testing.assert_allclose(adapter.act_batch(step.observation), expected, atol=1e-4)


def test_evaluation_scenario_keeps_the_observation_and_the_papers_rules():
    evaluation = evaluation_scenario(training_scenario("paper"))
    assert evaluation.observation.route_offset
    assert evaluation.episode.reward == "train" and evaluation.episode.action == "acceleration"
    assert evaluation.episode.corridor_width == 0.0
    assert evaluation.collision.mode == "none"
    margin = training_scenario("paper", collision__obstacle_distance=2.0)
    assert evaluation_scenario(margin).collision.obstacle_distance == 0.0  # the paper's: inside


def test_reward_train_through_every_view():
    env = parallel_env("track", reward="train", duration=20.0)
    parallel_api_test(env, num_cycles=20)
    env.reset(seed=0)
    _, rewards, _, _, infos = env.step({a: np.zeros(3) for a in env.agents})
    info = infos["uav_0"]
    assert rewards["uav_0"] == pytest.approx(sum(info[f"reward_{t}"] for t in TERMS))
    assert env.observation_space("uav_0").shape == (19 + 7 * 4 + 2,)
    gym_env = gym.make(uav_formation_env.TRAIN_GYM_ID)
    assert gym_env.unwrapped.parallel.scenario.episode.reward == "train"
    assert parallel_env("paper").scenario.episode.reward == "raw"  # the paper's default stays


def test_bad_training_options_name_the_field():
    with pytest.raises(ValueError, match="reward must be one of"):
        parallel_env("paper", reward="dense")
    with pytest.raises(ValueError, match="episode.action"):
        training_scenario("paper", episode__action="jerk")
    with pytest.raises(ValueError, match="episode.train.route_scale"):
        training_scenario("paper", episode__train__route_scale=0.0)
