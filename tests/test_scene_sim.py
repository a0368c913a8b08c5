"""Scene distributions in the simulator, the episode layer, the env and the runner: a scene per
copy per reset, named by the copy's seed whatever the batch."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from uav_formation_env.config import ObstacleFieldConfig, SceneConfig
from uav_formation_env.config_io import resolve_scenario, with_overrides
from uav_formation_env.evaluation import run_episodes, summarise
from uav_formation_env.policies import make_policy
from uav_formation_env.policies.heuristic import consensus_pd
from uav_formation_env.scenes import draw_scene
from uav_formation_env.sim import FormationSim

# 60 s: at 40 s 48 of 3000 seeds found no room for their obstacles (the checkers reset unseeded)
RANDOM_FIELDS = with_overrides(resolve_scenario("random_fields"), {"duration": 60.0})


def _centres(scene) -> list[tuple[float, float]]:
    return [o.center for o in scene.avoidance.obstacles]


def _fly(sim: FormationSim, steps: int) -> np.ndarray:
    """States (steps + 1, B, N, 6) under the consensus PD controller."""
    states = [sim.z.copy()]
    for _ in range(steps):
        last = sim.last
        sim.step(consensus_pd(sim.z, last.reference_velocity, last.adjacency, sim.offsets, 5.0))
        states.append(sim.z.copy())
    return np.stack(states)


def test_different_seeds_draw_different_fields_and_a_seed_its_own():
    sim = FormationSim(RANDOM_FIELDS, batch_size=3)
    sim.reset(seed=[5, 6, 5])
    assert _centres(sim.scenes[0]) != _centres(sim.scenes[1])
    assert _centres(sim.scenes[0]) == _centres(sim.scenes[2])
    # the scene of a seed is draw_scene on the seed's generator, drawn before the start positions
    assert sim.scenes[1] == draw_scene(RANDOM_FIELDS, np.random.default_rng(6))
    # a later reset of the same copies with other seeds draws other fields
    sim.reset(seed=[7, 8, 9])
    assert _centres(sim.scenes[0]) != _centres(sim.scenes[2])


def test_a_seed_names_the_same_episode_alone_or_inside_a_batch():
    batch = FormationSim(RANDOM_FIELDS, batch_size=3)
    batch.reset(seed=[11, 4, 12])
    alone = FormationSim(RANDOM_FIELDS, batch_size=1)
    alone.reset(seed=4)
    assert alone.scenes[0] == batch.scenes[1]
    np.testing.assert_array_equal(batch.obstacles.centres[1], alone.obstacles.centres[0])
    together, single = _fly(batch, 150), _fly(alone, 150)
    np.testing.assert_array_equal(together[:, 1], single[:, 0])


def test_the_drawn_obstacles_are_the_ones_the_topology_avoids():
    """The avoidance reacts to the copy's own field: a copy whose field is cleared never
    activates an obstacle, while the drawn field on the route does."""
    sim = FormationSim(with_overrides(RANDOM_FIELDS, {"duration": 200.0}), batch_size=2)
    sim.reset(seed=[1, 2])
    sim.obstacles.set_copy(1, replace(RANDOM_FIELDS.avoidance, obstacles=()))
    _fly(sim, 1000)
    status = sim.topology.status
    assert (status[0][sim.obstacles.present[0]] != 0).any()  # the drawn field was avoided
    assert (status[0][~sim.obstacles.present[0]] == 0).all()  # padding never activates
    assert (status[1] == 0).all()


def test_each_copy_measures_its_own_drawn_obstacles_not_the_padding():
    sim = FormationSim(RANDOM_FIELDS, batch_size=4)
    sim.reset(seed=[0, 1, 2, 3])
    counts = sim.obstacles.present.sum(axis=1)
    assert sim.obstacles.count == 4 and counts.min() < 4  # some copies are padded
    _fly(sim, 100)
    _, surface = sim.distances()
    for b, scene in enumerate(sim.scenes):  # by hand from the copy's concrete scenario
        p = sim.z[b, :, None, :2]
        centres = np.array(_centres(scene))
        radii = np.array([o.radius for o in scene.avoidance.obstacles])
        expected = (np.linalg.norm(p - centres, axis=-1) - radii).min(axis=1)
        np.testing.assert_allclose(surface[b], expected, rtol=1e-12)


def test_per_copy_wind_is_the_drawn_wind():
    scene = SceneConfig(wind=(0.3, 0.3))
    scenario = replace(
        resolve_scenario("paper"),
        disturbance=replace(resolve_scenario("paper").disturbance, model="none"),
        scene=scene,
    )
    sim = FormationSim(scenario, batch_size=3)
    sim.reset(seed=[0, 1, 2])
    result = sim.step(np.zeros((3, 5, 3)))
    for b in range(3):
        wind = np.asarray(sim.scenes[b].disturbance.wind)
        assert np.linalg.norm(wind) == pytest.approx(0.3)
        np.testing.assert_allclose(result.disturbance[b], np.broadcast_to(wind, (5, 3)))
    assert not np.allclose(result.disturbance[0], result.disturbance[1])


def test_a_sim_of_a_distribution_over_n_has_one_n_and_refuses_other_seeds_unchanged():
    swarm = resolve_scenario("random_swarm")
    with pytest.raises(ValueError, match="pass n_uav"):
        FormationSim(swarm)
    seeds_by_n: dict[int, int] = {}
    for seed in range(40):
        seeds_by_n.setdefault(draw_scene(swarm, np.random.default_rng(seed)).n_uav, seed)
    (n, seed), (other_n, other) = list(seeds_by_n.items())[:2]
    sim = FormationSim(swarm, batch_size=1, n_uav=n)
    first = sim.reset(seed=seed)
    assert sim.scenes[0].n_uav == n and first.z.shape == (1, n, 6)
    z = sim.z.copy()
    with pytest.raises(ValueError, match=f"{other_n} UAVs"):
        sim.reset(seed=other)
    np.testing.assert_array_equal(sim.z, z)  # the refused reset changed nothing
    sim.step(np.zeros((1, n, 3)))


def test_runner_reports_each_seed_on_its_own_field():
    policy = make_policy("heuristic", RANDOM_FIELDS)
    batch = run_episodes(RANDOM_FIELDS, policy, seeds=[0, 1, 2])
    assert [s.avoidance.obstacles for s in batch.scenes] == [
        draw_scene(RANDOM_FIELDS, np.random.default_rng(s)).avoidance.obstacles for s in (0, 1, 2)
    ]
    mission = summarise(batch)["mission"]
    present = np.array([mission["obstacles"][f"O{o + 1}"]["present_per_seed"] for o in range(4)])
    counts = [len(s.avoidance.obstacles) for s in batch.scenes]
    np.testing.assert_array_equal(present.sum(axis=0), counts)
    for o in range(4):  # a padding obstacle is neither required nor met
        info = mission["obstacles"][f"O{o + 1}"]
        for b in range(3):
            if not info["present_per_seed"][b]:
                assert not info["required_per_seed"][b] and not info["met_per_seed"][b]


def test_obstacle_field_config_with_no_obstacles_gives_empty_fields():
    empty = SceneConfig(obstacles=ObstacleFieldConfig(count=(0, 0)))
    scenario = replace(RANDOM_FIELDS, scene=empty)
    sim = FormationSim(scenario, batch_size=2)
    sim.reset(seed=[0, 1])
    assert sim.obstacles.count == 0
    _fly(sim, 5)


def test_every_checker_passes_on_random_fields():
    import warnings

    import gymnasium
    from gymnasium.utils.env_checker import check_env as gym_check_env
    from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test

    from uav_formation_env import GYM_ID
    from uav_formation_env.envs import env, parallel_env

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # advisory checker warnings (e.g. infinite state bounds)
        parallel_api_test(parallel_env(scenario=RANDOM_FIELDS), num_cycles=50)
        parallel_seed_test(lambda: parallel_env(scenario=RANDOM_FIELDS), num_cycles=50)
        api_test(env(scenario=RANDOM_FIELDS), num_cycles=50)
        gym_check_env(gymnasium.make(GYM_ID, scenario=RANDOM_FIELDS).unwrapped)
    e = parallel_env(scenario=RANDOM_FIELDS)
    e.reset(seed=3)
    first = _centres(e.sim.scenes[0])
    e.reset(seed=4)
    assert _centres(e.sim.scenes[0]) != first


def test_one_observation_space_for_every_n_with_the_local_layout():
    import warnings

    from pettingzoo.test import parallel_api_test

    from uav_formation_env.envs import parallel_env

    local = {"observation.kind": "local"}
    swarm = parallel_env("random_swarm")
    shape = swarm.observation_space("uav_0").shape
    assert shape == (95,)  # 19 + 11 (4 neighbour + 2 proximity slots) + 5 * 2 obstacle slots
    for other in ("swarm_100", "paper"):
        scenario = with_overrides(resolve_scenario(other), local)
        assert parallel_env(scenario=scenario).observation_space("uav_0").shape == shape
    assert parallel_env("paper").observation_space("uav_0").shape == (47,)  # Table 2's layout
    sizes = set()
    for seed in range(6):
        obs, _ = swarm.reset(seed=seed)
        n = draw_scene(swarm.scenario, np.random.default_rng(seed)).n_uav
        assert swarm.agents == [f"uav_{i}" for i in range(n)]
        assert list(obs) == swarm.possible_agents  # absent agents: zero observations
        assert all(o.shape == shape for o in obs.values())
        assert all(not obs[a].any() for a in swarm.possible_agents[n:])
        sizes.add(n)
    assert len(sizes) > 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        parallel_api_test(parallel_env("random_swarm"), num_cycles=60)


def test_reference_policies_refuse_what_they_cannot_decode():
    # the full layout with a drawn formation: the offsets are in neither the scenario nor the obs
    for name in ("lfpio", "heuristic"):
        with pytest.raises(ValueError, match="draws it per reset.*observation.kind='local'"):
            make_policy(
                name,
                replace(resolve_scenario("random_swarm"), observation=RANDOM_FIELDS.observation),
            )
        make_policy(name, resolve_scenario("random_swarm"))  # the local layout: accepted
