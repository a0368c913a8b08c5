"""Obstacle geometry, the preset schedule and the topology update on torch (core/obstacles.py,
core/reference.py, core/topology.py).

numpy is the reference: torch float64 (on the CPU, and on CUDA when present) must give the same
numbers (floats to 1e-12, integers and flags exactly), for single calls on random inputs and for
whole sequences of topology updates replayed from numpy :class:`FormationSim` runs through the
paper's avoidance (activation, split, guides, restore around t = 30-70 s) and through drawn
per-copy obstacle fields and routes (``concurrent``, ``rearm``, ``route_gain``).
"""

from __future__ import annotations

import copy as copy_module
import dataclasses
from dataclasses import replace

import numpy as np
import pytest

from uav_formation_env.config import AvoidanceConfig, ObstacleConfig, ScheduleConfig
from uav_formation_env.config_io import SCENARIOS
from uav_formation_env.core import array_api
from uav_formation_env.core.array_api import to_numpy
from uav_formation_env.core.obstacles import (
    choose_sides,
    deflection_demand,
    field_like,
    heading_frame,
    in_range,
    obstacle_distances,
    obstacle_field,
    relative_geometry,
    tangent_direction,
)
from uav_formation_env.core.reference import (
    CopySchedules,
    copy_schedules,
    next_leg,
    preset_displacement,
    preset_velocity,
    reference_preview,
    route_error,
)
from uav_formation_env.core.topology import (
    TopologyOutput,
    TopologyState,
    init_topology,
    reset_topology,
    route_correction,
    update_topology,
)
from uav_formation_env.scenarios import make_scenario
from uav_formation_env.sim import FormationSim

torch = pytest.importorskip("torch")

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
TOL = dict(rtol=1e-12, atol=1e-12)
SCHEDULE = ScheduleConfig()  # the paper's: +x, +y at 50 s, -x at 100 s, -y at 150 s
SHORT = ScheduleConfig(times=(5.0,), velocities=((10.0, 0.0, 0.0), (0.0, 10.0, 1.0)))
STILL = ScheduleConfig(times=(), velocities=((0.0, 0.0, 3.0),))  # one leg, no horizontal part


def on(x, device):
    """A numpy array (or a dataclass of them) as torch, same dtype, on ``device``."""
    if x is None:
        return None
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return type(x)(**{f.name: on(getattr(x, f.name), device) for f in dataclasses.fields(x)})
    return torch.as_tensor(np.array(x), device=device)


def check(expected, got, what=""):
    """``got`` (torch) equals ``expected`` (numpy): dtype, shape and values."""
    if dataclasses.is_dataclass(expected):
        for f in dataclasses.fields(expected):
            check(getattr(expected, f.name), getattr(got, f.name), f"{what}.{f.name}")
        return
    assert isinstance(got, torch.Tensor), what
    value = to_numpy(got)
    expected = np.asarray(expected)
    assert value.dtype == expected.dtype, (what, value.dtype, expected.dtype)
    assert value.shape == expected.shape, (what, value.shape, expected.shape)
    if expected.dtype.kind == "f":
        np.testing.assert_allclose(value, expected, err_msg=what, **TOL)
    else:
        np.testing.assert_array_equal(value, expected, err_msg=what)


# --- shim additions ------------------------------------------------------------------------------


@pytest.mark.parametrize("device", DEVICES)
def test_shim_take_amin_as_float_and_constants(device):
    rng = np.random.default_rng(0)
    x, index = rng.normal(size=(4, 5, 3)), rng.integers(0, 5, size=(2, 3))
    for axis in (0, 1, -1):
        idx = index % x.shape[axis]
        check(
            array_api.take(x, idx, axis=axis), array_api.take(on(x, device), on(idx, device), axis)
        )
        check(array_api.amin(x, axis), array_api.amin(on(x, device), axis))
    check(array_api.amin(x, 1, keepdims=True), array_api.amin(on(x, device), 1, keepdims=True))
    # as_float: numpy stays numpy; torch floats pass through; others follow `like`
    assert array_api.as_float([1, 2]).dtype == np.float64
    ints = np.arange(3)
    assert array_api.as_float(ints).dtype == np.float64
    like = on(x, device)
    moved = array_api.as_float(ints, like=like)
    assert moved.dtype == torch.float64 and moved.device == like.device
    assert array_api.as_float(like) is like
    single = like.to(torch.float32)
    assert array_api.as_float(ints, like=single).dtype == torch.float32
    assert array_api.float_dtype(torch.arange(3)) == torch.float64
    assert array_api.float_dtype(None) == np.float64
    # constant_like: numpy like -> the array itself; torch -> one cached tensor per device
    constant = np.arange(4.0)
    constant.flags.writeable = False
    assert array_api.constant_like(constant, x) is constant
    first = array_api.constant_like(constant, like)
    assert first is array_api.constant_like(constant, like)
    assert first.device == like.device and first.dtype == torch.float64
    check(constant, first)


# --- schedule ------------------------------------------------------------------------------------


def per_copy(batch: int) -> CopySchedules:
    """Different schedules per copy, padded (one with no switching time at all)."""
    pool = [SCHEDULE, SHORT, STILL]
    return copy_schedules([pool[b % 3] for b in range(batch)])


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("schedule", [SCHEDULE, SHORT, STILL], ids=["paper", "short", "still"])
def test_shared_schedule_functions_equal(device, schedule):
    rng = np.random.default_rng(1)
    # switching times exactly (the 1e-9 s tolerance), before 0 and after the last leg
    t = np.concatenate(
        [[0.0, 5.0, 50.0, 100.0, 150.0 + 1e-10, -1.0, 400.0], rng.uniform(0, 220, 9)]
    )
    for shape in [(), (16,), (4, 4)]:
        tt = t[0] if shape == () else t.reshape(shape)
        check(preset_velocity(schedule, tt), preset_velocity(schedule, on(tt, device)))
        for a, b in zip(next_leg(schedule, tt), next_leg(schedule, on(tt, device)), strict=True):
            check(a, b)
        positive = np.abs(tt)
        check(
            preset_displacement(schedule, positive),
            preset_displacement(schedule, on(positive, device)),
        )


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("batch", [1, 5])
def test_per_copy_schedule_functions_equal(device, batch):
    rng = np.random.default_rng(2)
    schedules = per_copy(batch)
    on_device = on(schedules, device)
    for shape in [(batch,), (batch, 7)]:
        t = rng.uniform(0, 220, size=shape)
        t[..., 0] = 50.0  # a switching time of the paper's schedule
        check(preset_velocity(schedules, t), preset_velocity(on_device, on(t, device)))
        # numpy times against a torch schedule follow the schedule's device
        check(preset_velocity(schedules, t), preset_velocity(on_device, t))
        for a, b in zip(next_leg(schedules, t), next_leg(on_device, on(t, device)), strict=True):
            check(a, b)
        check(preset_displacement(schedules, t), preset_displacement(on_device, on(t, device)))
    # a schedule of one leg only (K = 0): next_leg's own velocity and no wait
    still = copy_schedules([STILL] * batch)
    t = rng.uniform(0, 9, size=batch)
    for a, b in zip(next_leg(still, t), next_leg(on(still, device), on(t, device)), strict=True):
        check(a, b)
    with pytest.raises(ValueError, match="copy axis first"):
        preset_velocity(on_device, torch.zeros(batch + 1, dtype=torch.float64, device=device))


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("batch", [1, 4])
@pytest.mark.parametrize("shared", [True, False])
def test_route_error_and_reference_preview_equal(device, batch, shared):
    rng = np.random.default_rng(3)
    schedule = SCHEDULE if shared else per_copy(batch)
    schedule_t = schedule if shared else on(schedule, device)
    n = 4
    t = rng.uniform(0, 200, size=batch)
    centroid, start = rng.normal(size=(batch, 3)) * 100, rng.normal(size=(batch, 3))
    check(
        route_error(schedule, t, centroid, start),
        route_error(schedule_t, on(t, device), on(centroid, device), on(start, device)),
    )
    reference = rng.normal(size=(batch, n, 3))
    correction = rng.normal(size=(batch, 3))
    for avoiding in (
        np.zeros((batch, n), bool),
        np.ones((batch, n), bool),
        rng.random((batch, n)) < 0.5,
    ):
        for corr in (None, correction):
            expected = reference_preview(schedule, t, 0.2, 10, reference, avoiding, corr)
            got = reference_preview(
                schedule_t,
                on(t, device),
                0.2,
                10,
                on(reference, device),
                on(avoiding, device),
                on(corr, device),
            )
            check(expected, got)
    # a scalar time with torch references
    check(
        reference_preview(schedule, 49.9, 0.2, 3, reference, avoiding),
        reference_preview(schedule_t, 49.9, 0.2, 3, on(reference, device), on(avoiding, device)),
    )


# --- obstacle geometry ---------------------------------------------------------------------------

THREE = AvoidanceConfig(
    obstacles=(
        ObstacleConfig((0.0, 0.0), 30.0),
        ObstacleConfig((200.0, 50.0), 20.0),
        ObstacleConfig((-100.0, -80.0), 10.0),
    )
)
NONE = AvoidanceConfig(obstacles=())


@pytest.mark.parametrize("device", DEVICES)
def test_obstacle_field_on_torch_set_copy_and_take(device):
    avoidances = [THREE, NONE, replace(THREE, obstacles=THREE.obstacles[:1])]
    expected = obstacle_field(avoidances, count=4)
    like = torch.zeros(1, dtype=torch.float64, device=device)
    field = obstacle_field(avoidances, count=4, like=like)
    check(expected, field)
    assert field_like(expected, np.zeros(1)) is expected
    check(expected, field_like(expected, like))
    back = field_like(field, np.zeros(1))  # and back to numpy
    for name in ("centres", "radii", "r_safe", "r_detect", "present"):
        np.testing.assert_array_equal(getattr(back, name), getattr(expected, name))
    # in-place row writes and copies between fields, as the simulator's resets do
    expected.set_copy(1, THREE)
    field.set_copy(1, THREE)
    expected.set_copy(0, NONE)
    field.set_copy(0, NONE)
    check(expected, field)
    source = obstacle_field([THREE] * 3, count=4)
    source_t = field_like(source, like)
    for mask in (np.array([True, False, True]), np.zeros(3, bool), np.ones(3, bool)):
        expected.take(mask, source)
        field.take(on(mask, device), source_t)
        check(expected, field)
    field.take(np.array([False, True, False]), source_t)  # a numpy mask on a torch field
    expected.take(np.array([False, True, False]), source)
    check(expected, field)
    empty = obstacle_field([NONE, NONE], like=like)
    assert (
        empty.count == 0 and empty.centres.shape == (2, 0, 2) and empty.present.dtype == torch.bool
    )


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("batch", [1, 6])
def test_geometry_functions_equal(device, batch):
    rng = np.random.default_rng(4)
    n = 5
    velocity = rng.normal(size=(batch, 3)) * 20
    velocity[0, :2] = 0.0  # no horizontal direction: a zero frame
    e_hat, n_hat = heading_frame(velocity)
    e_t, n_t = heading_frame(on(velocity, device))
    check(e_hat, e_t)
    check(n_hat, n_t)
    positions = rng.normal(size=(batch, n, 3)) * 60
    positions[-1, 0, :2] = (200.0, 50.0)  # exactly on an obstacle centre: D = 0
    field = obstacle_field([THREE] * batch)
    field_t = on(field, device)
    shared = np.asarray([o.center for o in THREE.obstacles])
    for centres, centres_t in (
        (shared, on(shared, device)),
        (shared, shared),
        (field.centres, field_t.centres),
    ):
        expected = relative_geometry(positions, centres, e_hat)
        got = relative_geometry(on(positions, device), centres_t, e_t)
        for a, b in zip(expected, got, strict=True):
            check(a, b)
    rel_x, rel_y, dist, lon, lat = expected
    rel_t = got
    r_safe = field.r_safe.T[:, None, :]
    check(in_range(lon, lat, r_safe), in_range(rel_t[3], rel_t[4], on(r_safe, device)))
    side = np.where(rng.random(dist.shape) < 0.5, 1, -1).astype(np.int8)
    for a, b in zip(
        tangent_direction(rel_x, rel_y, dist, r_safe, side),
        tangent_direction(rel_t[0], rel_t[1], rel_t[2], on(r_safe, device), on(side, device)),
        strict=True,
    ):
        check(a, b)
    check(obstacle_distances(positions, THREE), obstacle_distances(on(positions, device), THREE))
    check(obstacle_distances(positions, field), obstacle_distances(on(positions, device), field_t))
    check(obstacle_distances(positions, NONE), obstacle_distances(on(positions, device), NONE))
    sl = np.array([1, -1], dtype=np.int8)
    for r, r_t in ((field.r_safe[0], field.r_safe[0]), (r_safe, on(r_safe, device))):
        check(
            deflection_demand(rel_x, rel_y, dist, r, e_hat, sl),
            deflection_demand(rel_t[0], rel_t[1], rel_t[2], r_t, e_t, sl),
        )
    # sides: all on one side, all within the deadband, split, and a member on the line
    lat_cases = [lat, np.abs(lat) + 1, -np.abs(lat) - 1, lat * 1e-3, np.zeros_like(lat)]
    for case in lat_cases:
        for deadband in (0.0, 5.0):
            for a, b in zip(
                choose_sides(case, deadband), choose_sides(on(case, device), deadband), strict=True
            ):
                check(a, b)


# --- topology state ------------------------------------------------------------------------------


@pytest.mark.parametrize("device", DEVICES)
def test_init_and_reset_topology_on_torch(device):
    like = torch.zeros(1, dtype=torch.float64, device=device)
    check(init_topology(3, 4, 2), init_topology(3, 4, 2, like=like))
    rng = np.random.default_rng(5)
    state = TopologyState(
        status=rng.integers(0, 3, (3, 2)).astype(np.int8),
        side=rng.choice(np.array([-1, 1], np.int8), (3, 2, 4)),
        guide=rng.integers(-1, 4, (3, 2, 2)),
        ended=rng.random((3, 2, 2)) < 0.5,
        case=rng.integers(0, 3, (3, 2)).astype(np.int8),
        activation_time=rng.uniform(0, 9, (3, 2)),
        restore_time=rng.uniform(0, 9, (3, 2)),
    )
    for mask in ([True, False, True], [False] * 3, [True] * 3):
        mask = np.array(mask)
        check(reset_topology(state, mask), reset_topology(on(state, device), on(mask, device)))
        check(reset_topology(state, mask), reset_topology(on(state, device), mask))


@pytest.mark.parametrize("device", DEVICES)
def test_update_without_obstacles_and_route_correction(device):
    rng = np.random.default_rng(6)
    positions, velocities = rng.normal(size=(2, 3, 3)), rng.normal(size=(2, 3, 3))
    h0 = np.ones((3, 3)) - np.eye(3)
    t = np.array([10.0, 60.0])
    state = init_topology(2, 3, 0)
    like = on(positions, device)
    avoidance = replace(NONE, route_gain=0.1, route_correction_max=2.0)
    start = rng.normal(size=(2, 3)) * 50
    expected = update_topology(
        state, positions, velocities, t, avoidance, SCHEDULE, h0, None, start
    )
    got = update_topology(
        init_topology(2, 3, 0, like=like),
        like,
        on(velocities, device),
        on(t, device),
        avoidance,
        SCHEDULE,
        on(h0, device),
        None,
        on(start, device),
    )
    check(expected[0], got[0])
    check(expected[1], got[1])
    check(
        route_correction(avoidance, SCHEDULE, t, positions, start),
        route_correction(avoidance, SCHEDULE, on(t, device), like, start),  # numpy start
    )


# --- whole sequences -----------------------------------------------------------------------------


def record(scenario, batch: int, seed: int, steps: int, gain: float = 0.6):
    """Run a numpy simulator with a velocity-tracking input and keep the topology's inputs."""
    sim = FormationSim(scenario, batch)
    result = sim.reset(seed=seed)
    setup = dict(
        avoidance=scenario.avoidance,
        schedule=copy_module.deepcopy(sim.schedule),
        h0=np.array(sim.base_adjacency),
        obstacles=copy_module.deepcopy(sim.obstacles),
        route_start=np.array(sim.route_start),
        n_obs=len(scenario.avoidance.obstacles) if sim.obstacles is None else sim.obstacles.count,
    )
    frames = []
    for _ in range(steps):
        v = np.asarray(result.z)[..., 3:]
        result = sim.step(gain * (np.asarray(result.reference_velocity) - v))
        z = np.asarray(result.z)
        frames.append((z[..., :3].copy(), z[..., 3:].copy(), np.array(sim.t)))
    return setup, frames


def replay(setup, frames, device):
    """Feed the frames to update_topology on numpy and on torch, each backend carrying its own
    state; compare every state and output field at every step. Returns the numpy outputs."""
    batch, n_uav = frames[0][0].shape[:2]
    n_obs = setup["n_obs"]
    like = torch.zeros(1, dtype=torch.float64, device=device)
    state, state_t = init_topology(batch, n_uav, n_obs), init_topology(batch, n_uav, n_obs, like)
    schedule = setup["schedule"]
    schedule_t = on(schedule, device) if isinstance(schedule, CopySchedules) else schedule
    obstacles = setup["obstacles"]
    obstacles_t = None if obstacles is None else field_like(obstacles, like)
    h0, start = setup["h0"], setup["route_start"]
    h0_t, start_t = on(h0, device), on(start, device)
    avoidance = setup["avoidance"]
    outputs: list[TopologyOutput] = []
    for k, (p, v, t) in enumerate(frames):
        state, out = update_topology(state, p, v, t, avoidance, schedule, h0, obstacles, start)
        state_t, out_t = update_topology(
            state_t,
            on(p, device),
            on(v, device),
            on(t, device),
            avoidance,
            schedule_t,
            h0_t,
            obstacles_t,
            start_t,
        )
        check(state, state_t, f"step {k} state")
        check(out, out_t, f"step {k} output")
        if k % 10 == 0:
            args = (t, 0.2, 10, out.reference_velocity, out.avoiding, out.route_correction)
            args_t = (on(t, device), 0.2, 10, out_t.reference_velocity, out_t.avoiding)
            check(
                reference_preview(schedule, *args),
                reference_preview(schedule_t, *args_t, out_t.route_correction),
                f"step {k} preview",
            )
        outputs.append(out)
    return outputs


def exercised(outputs, split: bool = True):
    """The replay went through activation, a split (two groups), avoidance and a restore."""
    assert any(o.activated.any() for o in outputs)
    assert any(o.restored.any() for o in outputs)
    assert any(o.avoiding.any() for o in outputs)
    if split:
        assert any((o.groups > 0).any() for o in outputs)


@pytest.fixture(scope="module")
def paper_run():
    return record(make_scenario(), batch=3, seed=0, steps=400)  # 80 s: both paper obstacles


@pytest.mark.parametrize("device", DEVICES)
def test_paper_sequence_equal(device, paper_run):
    exercised(replay(*paper_run, device))


@pytest.mark.parametrize("device", DEVICES)
def test_paper_sequence_single_copy_current_speed_base_graph(device):
    scenario = make_scenario()
    avoidance = replace(scenario.avoidance, reference_speed="current", split_graph="base")
    setup, frames = record(replace(scenario, avoidance=avoidance), batch=1, seed=1, steps=380)
    exercised(replay(setup, frames, device))


@pytest.mark.parametrize("device", DEVICES)
def test_paper_sequence_with_pace_keeping(device):
    scenario = make_scenario()
    avoidance = replace(scenario.avoidance, pace_limit=1.4)
    setup, frames = record(replace(scenario, avoidance=avoidance), batch=2, seed=2, steps=380)
    outputs = replay(setup, frames, device)
    exercised(outputs)
    speeds = [np.linalg.norm(o.reference_velocity[o.avoiding], axis=-1) for o in outputs]
    assert max(s.max() for s in speeds if s.size) > 20.5  # the pace rule ran


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("name", ["random_routes", "random_fields"])
def test_drawn_per_copy_fields_and_routes_equal(device, name):
    scenario = SCENARIOS[name]()
    assert scenario.avoidance.concurrent and scenario.avoidance.route_gain > 0
    setup, frames = record(scenario, batch=4, seed=3, steps=450)
    assert setup["obstacles"] is not None
    assert (name == "random_routes") == isinstance(setup["schedule"], CopySchedules)
    outputs = replay(setup, frames, device)
    exercised(outputs, split=False)
    assert any(np.abs(o.route_correction).max() > 0 for o in outputs)  # the route return ran
