"""Pair terms within a sensing radius (core.proximity): the grid finds exactly the pairs within R,
and J_i, collisions and the local observation built from them equal the all-pairs ones wherever
the all-pairs answer lies within R."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uav_formation_env.config_io import resolve_scenario, with_overrides
from uav_formation_env.core import proximity
from uav_formation_env.core.cost import stage_cost
from uav_formation_env.core.cost.stage import pair_distances
from uav_formation_env.core.local_observation import build_local_observations
from uav_formation_env.core.proximity import sensed_pairs
from uav_formation_env.episode import FormationEpisodes


def brute_force(positions: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    distance = pair_distances(positions)
    b, i, j = np.nonzero(distance <= radius)
    return np.stack([b * positions.shape[1] + i, j], axis=1), distance[b, i, j]


@settings(max_examples=60, deadline=None)
@given(
    batch=st.integers(1, 4),
    n_uav=st.integers(2, 30),
    spread=st.sampled_from([5.0, 40.0, 300.0, 1e8]),  # 1e8 m: cell coordinates wrap
    radius=st.sampled_from([2.0, 10.0, 25.0]),
    seed=st.integers(0, 2**16),
)
def test_the_grid_finds_exactly_the_pairs_within_the_radius(batch, n_uav, spread, radius, seed):
    rng = np.random.default_rng(seed)
    positions = rng.normal(size=(batch, n_uav, 3)) * spread
    positions[1::2, ::3] = positions[1::2, :1]  # some UAVs on top of each other
    pairs = sensed_pairs(positions, radius)
    expected, distance = brute_force(positions, radius)
    np.testing.assert_array_equal(np.stack([pairs.receiver, pairs.sender], axis=1), expected)
    np.testing.assert_allclose(pairs.distance, distance, rtol=1e-12, atol=1e-9)
    nearest = pair_distances(positions).min(axis=-1)
    np.testing.assert_allclose(
        pairs.nearest(), np.where(nearest <= radius, nearest, np.inf), rtol=1e-12, atol=1e-9
    )


def test_batches_larger_than_the_key_space_are_split(monkeypatch):
    positions = np.random.default_rng(0).normal(size=(7, 12, 3)) * 10
    whole = sensed_pairs(positions, 8.0)
    monkeypatch.setattr(proximity, "_MAX_COPIES", 3)
    split = sensed_pairs(positions, 8.0)
    for name in ("receiver", "sender", "distance"):
        np.testing.assert_array_equal(getattr(split, name), getattr(whole, name))


def test_separation_term_and_nearest_distance_equal_all_pairs():
    scenario = resolve_scenario("swarm_20")
    rng = np.random.default_rng(1)
    z = np.zeros((3, 20, 6))
    z[..., :2] = rng.uniform(0, 40, (3, 20, 2))  # crowded: many pairs closer than d_s = 10 m
    z[..., 3:] = rng.normal(size=(3, 20, 3))
    args = (
        z,
        rng.normal(size=(3, 20, 3)),
        np.broadcast_to([20.0, 0.0, 0.0], (3, 20, 3)),
        np.broadcast_to(np.asarray(scenario.formation.adjacency, float), (3, 20, 20)),
        np.asarray(scenario.formation.offsets),
        scenario.cost,
    )
    dense = stage_cost(*args, pair_distance=pair_distances(z[..., :3]))
    sparse = stage_cost(*args, pair_distance=sensed_pairs(z[..., :3], 10.0))
    assert (dense.separation > 0).mean() > 0.5  # the term is on for most UAVs here
    np.testing.assert_allclose(sparse.separation, dense.separation, rtol=1e-12)
    np.testing.assert_array_equal(sparse.formation, dense.formation)


def observations(positions: np.ndarray, adjacency: np.ndarray, distance, radius=None) -> tuple:
    batch, n_uav = positions.shape[:2]
    z = np.concatenate([positions, np.zeros_like(positions)], axis=-1)
    zeros = np.zeros((batch, n_uav, 3))
    local = build_local_observations(
        z,
        zeros,
        zeros,
        adjacency,
        np.zeros((batch, n_uav), dtype=bool),
        np.zeros(batch),
        np.zeros((n_uav, 6)),
        np.zeros((batch, 0, 2)),
        np.zeros((batch, 0)),
        np.zeros((batch, 0), dtype=bool),
        np.zeros((batch, n_uav)),
        k=3,
        m=1,
        nearest=2,
        distance=distance,
        sensing_radius=radius,
    )
    return local.obs, local.neighbour_index


@pytest.mark.parametrize("seed", range(5))
def test_slots_from_sensed_pairs(seed):
    rng = np.random.default_rng(seed)
    batch, n_uav, radius = 2, 25, 12.0
    positions = rng.uniform(0, 60, (batch, n_uav, 3)) * [1, 1, 0.1]
    adjacency = (rng.random((batch, n_uav, n_uav)) < 0.1).astype(float)
    adjacency[:, np.arange(n_uav), np.arange(n_uav)] = 0
    dense_obs, dense_index = observations(positions, adjacency, pair_distances(positions))
    # a radius that holds everyone: the same slots as all pairs
    far_obs, far_index = observations(positions, adjacency, sensed_pairs(positions, 1e4))
    np.testing.assert_array_equal(far_index, dense_index)
    np.testing.assert_allclose(far_obs, dense_obs, atol=1e-6)
    # a small radius: every slot holds an in-neighbour or a UAV within R, and the slots are the
    # all-pairs rule applied to exactly those UAVs
    obs, index = observations(positions, adjacency, sensed_pairs(positions, radius))
    # the distance matrix with the radius (below GRID_MIN_UAVS): the same slots
    matrix_obs, matrix_index = observations(positions, adjacency, pair_distances(positions), radius)
    np.testing.assert_array_equal(matrix_index, index)
    np.testing.assert_allclose(matrix_obs, obs, atol=1e-6)
    distance = pair_distances(positions)
    known = (adjacency != 0) | (distance <= radius)
    hidden = np.where(known, distance, np.inf)  # the others: as if infinitely far
    reference = dense_index.copy()
    for b in range(batch):
        for i in range(n_uav):
            neighbours = sorted(
                np.flatnonzero(adjacency[b, i]), key=lambda j: (distance[b, i, j], j)
            )
            others = sorted(
                (j for j in np.flatnonzero(known[b, i]) if not adjacency[b, i, j]),
                key=lambda j: (hidden[b, i, j], j),
            )
            slots = (neighbours + others)[:3]
            rest = sorted(
                (j for j in np.flatnonzero(known[b, i]) if j not in slots),
                key=lambda j: (hidden[b, i, j], j),
            )[:2]
            reference[b, i] = (slots + [-1] * 3)[:3] + (rest + [-1] * 2)[:2]
    np.testing.assert_array_equal(index, reference)
    assert (index == -1).any() and (index >= 0).any()


def test_scenario_needs_a_radius_that_sees_every_close_pair():
    with pytest.raises(ValueError, match=r"observation\.sensing_radius.*>= cost\.separation"):
        with_overrides(resolve_scenario("swarm_20"), {"observation.sensing_radius": 5.0})
    with pytest.raises(ValueError, match=r"observation\.sensing_radius.*> 0"):
        with_overrides(resolve_scenario("swarm_20"), {"observation.sensing_radius": -1.0})


def test_the_env_rewards_and_collisions_do_not_depend_on_the_sensing_radius():
    base = with_overrides(resolve_scenario("swarm_20"), {"observation.sensing_radius": None})
    runs = []
    for radius in (None, 10.0):
        scenario = with_overrides(base, {"observation.sensing_radius": radius})
        episodes = FormationEpisodes(scenario, 2, fly_on_after_collision=True)
        episodes.reset(seed=[3, 4])
        rng = np.random.default_rng(0)
        rewards, collisions = [], []
        for _ in range(40):
            step = episodes.step(rng.uniform(-1, 1, (2, 20, 3)))
            rewards.append(step.reward)
            collisions.append(step.result.collision)
        runs.append((np.array(rewards), np.array(collisions), step.result.cost.separation))
    (r_all, c_all, s_all), (r_near, c_near, s_near) = runs
    np.testing.assert_allclose(r_near, r_all, rtol=1e-12)
    np.testing.assert_array_equal(c_near, c_all)
    assert (s_all > 0).any()  # the random inputs did bring UAVs within d_s


def test_every_checker_passes_on_a_swarm_with_a_sensing_radius():
    import warnings

    import gymnasium
    from gymnasium.utils.env_checker import check_env as gym_check_env
    from pettingzoo.test import parallel_api_test, parallel_seed_test

    from uav_formation_env import GYM_ID
    from uav_formation_env.envs import parallel_env

    swarm = with_overrides(resolve_scenario("swarm_20"), {"duration": 20.0})
    assert swarm.observation.sensing_radius is not None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # advisory checker warnings (e.g. infinite state bounds)
        parallel_api_test(parallel_env(scenario=swarm), num_cycles=30)
        parallel_seed_test(lambda: parallel_env(scenario=swarm), num_cycles=30)
        gym_check_env(gymnasium.make(GYM_ID, scenario=swarm).unwrapped)


def test_the_grid_and_the_matrix_fly_the_same_episode(monkeypatch):
    # swarm_20 uses the matrix (N < GRID_MIN_UAVS); forcing the grid must change nothing but
    # float rounding: the same observations, slots, rewards and collisions
    scenario = resolve_scenario("swarm_20")
    runs = []
    for threshold in (proximity.GRID_MIN_UAVS, 2):
        monkeypatch.setattr(proximity, "GRID_MIN_UAVS", threshold)
        episodes = FormationEpisodes(scenario, 2, fly_on_after_collision=True)
        step = episodes.reset(seed=[5, 6])
        assert isinstance(episodes.sim._pair_of[1], proximity.SensedPairs) == (threshold == 2)
        rng = np.random.default_rng(1)
        record = []
        for _ in range(30):
            step = episodes.step(rng.uniform(-1, 1, (2, 20, 3)))
            record.append((step.observation, step.neighbour_index, step.reward))
        runs.append(record)
    for (obs_a, index_a, reward_a), (obs_b, index_b, reward_b) in zip(*runs):
        np.testing.assert_array_equal(index_a, index_b)
        np.testing.assert_allclose(obs_a, obs_b, atol=1e-6)
        np.testing.assert_allclose(reward_a, reward_b, rtol=1e-12)
