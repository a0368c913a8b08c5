"""Drawn routes: one preset schedule per copy (core.reference.CopySchedules) in the schedule
functions, the simulator, the policies' previews, the mission metrics and the env checkers."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from uav_formation_env.config import ScheduleConfig
from uav_formation_env.config_io import resolve_scenario, with_overrides
from uav_formation_env.core.local_observation import decode_local_observations
from uav_formation_env.core.observation import require_decodable
from uav_formation_env.core.reference import (
    blend_offset,
    blended_velocity,
    copy_schedules,
    next_leg,
    preset_displacement,
    preset_velocity,
    reference_preview,
    route_error,
)
from uav_formation_env.episode import FormationEpisodes
from uav_formation_env.evaluation.mission import mission_metrics
from uav_formation_env.policies.broadcast import observed_schedule, observed_time
from uav_formation_env.policies.heuristic import consensus_pd
from uav_formation_env.sim import FormationSim

SCHEDULES = [
    ScheduleConfig(),  # the paper's: 4 legs, switches at 50, 100, 150 s
    ScheduleConfig(times=(30.5,), velocities=((0.0, 15.0, 0.0), (12.0, 9.0, 0.0))),
    ScheduleConfig(times=(), velocities=((-18.0, 2.0, 1.0),)),  # one leg
]
# every switching time exactly, either side of it, and beyond the last
TIMES = np.array([0.0, 10.0, 30.5, 30.5 + 1e-6, 49.9, 50.0, 50.2, 100.0, 150.0, 150.1, 260.0])
ROUTES = with_overrides(resolve_scenario("random_routes"), {"duration": 60.0})


def test_per_copy_functions_equal_each_copy_on_its_own():
    stacked = copy_schedules(SCHEDULES)
    assert stacked.times.shape == (3, 3) and stacked.velocities.shape == (3, 4, 3)
    t = np.broadcast_to(TIMES, (3, len(TIMES)))
    velocity, (following, wait) = preset_velocity(stacked, t), next_leg(stacked, t)
    displacement = preset_displacement(stacked, t)
    centroid = np.random.default_rng(0).normal(size=(3, len(TIMES), 3)) * 50
    start = np.ones((3, 1, 3))
    error = route_error(stacked, t, centroid, start)
    for b, schedule in enumerate(SCHEDULES):
        np.testing.assert_array_equal(velocity[b], preset_velocity(schedule, TIMES))
        single_next, single_wait = next_leg(schedule, TIMES)
        np.testing.assert_array_equal(following[b], single_next)
        np.testing.assert_array_equal(wait[b], single_wait)
        np.testing.assert_allclose(
            displacement[b], preset_displacement(schedule, TIMES), rtol=1e-12, atol=1e-9
        )
        np.testing.assert_allclose(
            error[b], route_error(schedule, TIMES, centroid[b], start[b]), rtol=1e-12
        )
    # hand-computed: copy 1 flies (0, 15) for 30.5 s, then (12, 9)
    np.testing.assert_allclose(displacement[1, -1], [12.0 * 229.5, 15 * 30.5 + 9.0 * 229.5, 0])
    with pytest.raises(ValueError, match=r"copy axis first, \(B=3"):
        preset_velocity(stacked, TIMES)


def test_each_copy_flies_its_own_drawn_route_and_a_seed_names_it():
    sim = FormationSim(ROUTES, batch_size=3)
    sim.reset(seed=[11, 12, 11])
    assert sim.scenes[0].schedule != sim.scenes[1].schedule
    assert sim.scenes[0].schedule == sim.scenes[2].schedule
    alone = FormationSim(ROUTES, batch_size=1)
    alone.reset(seed=12)
    for _ in range(150):  # 30 s: past the first turn of every copy
        for s in (sim, alone):
            last = s.last
            s.step(consensus_pd(s.z, last.reference_velocity, last.adjacency, s.offsets, 5.0))
        free = ~sim.last.avoiding  # (B, N): UAVs on the preset velocity, corners blended
        for b in range(3):
            own = blended_velocity(sim.scenes[b].schedule, sim.t[b], ROUTES.avoidance.turn_blend)
            own = own + sim.last.route_correction[b]
            mine = sim.last.reference_velocity[b][free[b]]
            # the sim blends all copies at once, this one copy: numpy (2.4.6) may round the
            # batched sum differently in the last bit
            np.testing.assert_allclose(mine, np.broadcast_to(own, mine.shape), rtol=1e-13)
    np.testing.assert_array_equal(alone.z[0], sim.z[1])
    np.testing.assert_array_equal(sim.z[0], sim.z[2])
    headings = {tuple(np.round(sim.last.reference_velocity[b, 0], 6)) for b in range(2)}
    assert len(headings) == 2


@pytest.mark.parametrize(("route_gain", "turn_blend"), [(0.0, 0.0), (0.1, 0.0), (0.05, 4.0)])
def test_the_policy_preview_from_the_local_observation_is_the_simulator_preview(
    route_gain, turn_blend
):
    scenario = with_overrides(
        ROUTES, {"avoidance.route_gain": route_gain, "avoidance.turn_blend": turn_blend}
    )
    episodes = FormationEpisodes(scenario, 4)
    step = episodes.reset(seed=[1, 2, 3, 4])
    sim, config, switches, corrected, blended = episodes.sim, ROUTES.observation, 0, 0, 0
    for _ in range(250):  # 50 s: every copy passes at least one turn
        decoded = decode_local_observations(
            step.observation, config.neighbours, config.obstacles, config.nearest
        )
        now = observed_time(decoded.time_fraction, ROUTES.duration, ROUTES.dynamics.dt)
        ours = reference_preview(
            observed_schedule(decoded, now.reshape(-1)),
            now.reshape(-1),
            ROUTES.dynamics.dt,
            ROUTES.cost.horizon,
            decoded.reference_velocity.reshape(-1, 1, 3),
            decoded.avoiding.reshape(-1, 1),
        ).reshape(4, 5, -1, 3)
        theirs = sim.reference_preview()
        np.testing.assert_allclose(ours, theirs, atol=1e-5)  # float32 slots
        corrected += int((np.abs(step.result.route_correction) > 0.1).any())
        offset = blend_offset(sim.schedule, sim.t, turn_blend)
        blended += int((np.abs(offset) > 0.1).any())
        switches += int((np.abs(np.diff(theirs, axis=2)).max(axis=-1) > 1).sum())
        last = step.result
        u = consensus_pd(sim.z, last.reference_velocity, last.adjacency, sim.offsets, 5.0)
        step = episodes.step(u)
    assert switches > 0  # the previews did cross turns
    assert (corrected > 0) == (route_gain > 0)  # and held a route-return term
    assert (blended > 0) == (turn_blend > 0)  # and a blended corner


def test_mission_route_error_is_measured_against_each_copys_own_route():
    sim = FormationSim(ROUTES, batch_size=2)
    sim.reset(seed=[11, 12])
    t = np.arange(0, 60.2, 0.2)
    start = sim.z[:, :, :3].mean(axis=1)  # (B, 3)
    # every UAV exactly on its copy's route: centroid = start + the copy's displacement
    route = np.stack(
        [start[b] + preset_displacement(sim.scenes[b].schedule, t) for b in range(2)], axis=1
    )
    z = np.zeros((len(t), 2, 5, 6))
    z[..., :3] = route[:, :, None, :] + (sim.z[:, :, :3] - start[:, None])[None]
    no = np.zeros((len(t) - 1, 2, 5), dtype=bool)
    far = np.full((len(t), 2, 5), 50.0)
    metrics = mission_metrics(ROUTES, t, z, no, far, sim.scenes)
    np.testing.assert_allclose(metrics.route_error_max, 0.0, atol=1e-9)
    # measured against copy 0's route, copy 1 is far off it
    shared = mission_metrics(ROUTES, t, z, no, far, [sim.scenes[0]] * 2)
    assert shared.route_error_max[1] > 100.0


def test_drawn_routes_need_the_local_layout_and_pass_every_checker():
    full = with_overrides(ROUTES, {"observation.kind": "full"})
    with pytest.raises(ValueError, match=r"scene.route.*observation.kind='local'"):
        require_decodable(full, "lfpio")
    require_decodable(ROUTES, "lfpio")

    import gymnasium
    from gymnasium.utils.env_checker import check_env as gym_check_env
    from pettingzoo.test import parallel_api_test, parallel_seed_test

    from uav_formation_env import GYM_ID
    from uav_formation_env.envs import parallel_env

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # advisory checker warnings (e.g. infinite state bounds)
        parallel_api_test(parallel_env(scenario=ROUTES), num_cycles=50)
        parallel_seed_test(lambda: parallel_env(scenario=ROUTES), num_cycles=50)
        gym_check_env(gymnasium.make(GYM_ID, scenario=ROUTES).unwrapped)


@pytest.mark.parametrize("kind", ["full", "local"])
def test_the_dmpc_previews_the_route_return_term_on_either_layout(kind):
    from uav_formation_env.core.observation import decode_observations
    from uav_formation_env.policies.broadcast import horizon_problems

    fields = with_overrides(
        resolve_scenario("random_fields"), {"duration": 60.0, "observation.kind": kind}
    )
    assert fields.avoidance.route_gain > 0
    episodes = FormationEpisodes(fields, 3)
    step = episodes.reset(seed=[0, 1, 2])
    sim, config, corrected = episodes.sim, fields.observation, 0
    plans = np.zeros((3, 5, fields.cost.horizon, 3))
    for _ in range(300):
        if kind == "full":
            decoded = decode_observations(step.observation, 5)
        else:
            decoded = decode_local_observations(
                step.observation, config.neighbours, config.obstacles, config.nearest
            )
            decoded = type(decoded)(**{**decoded.__dict__, "neighbour_index": step.neighbour_index})
        preview = horizon_problems(decoded, plans, fields).cost.reference_preview
        np.testing.assert_allclose(preview, sim.reference_preview(), atol=1e-5)
        corrected += int((np.abs(step.result.route_correction) > 0.1).any())
        last = step.result
        u = consensus_pd(sim.z, last.reference_velocity, last.adjacency, sim.offsets, 5.0)
        step = episodes.step(u)
    assert corrected > 0
