"""Obstacle avoidance with topology reconstruction (docs/model.md §7) on constructed geometries.

Unless a test says otherwise: one obstacle at the origin, radius 30 m, so R_s = 40 m and
d^o = 70 m; t = 10 s, so the preset velocity is (20, 0, 0) and ê = +x, n̂ = +y.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uav_formation_env.config import AvoidanceConfig, ObstacleConfig, ScheduleConfig
from uav_formation_env.core.obstacles import (
    heading_frame,
    in_range,
    obstacle_arrays,
    relative_geometry,
    tangent_direction,
)
from uav_formation_env.core.topology import (
    ACTIVE,
    DONE,
    IDLE,
    TopologyState,
    _turn_geometry,
    init_topology,
    obstacle_distances,
    preset_velocity,
    reference_preview,
    reset_topology,
    update_topology,
)

R_S = 40.0
D_O = 70.0
SCHEDULE = ScheduleConfig()
ONE = AvoidanceConfig(obstacles=(ObstacleConfig((0.0, 0.0), 30.0),))
PRESET = np.array([20.0, 0.0, 0.0])


def ring(n: int) -> np.ndarray:
    """A directed ring, so that H0 differs from every complete / block graph."""
    return np.roll(np.eye(n), 1, axis=1)


def complete(n: int) -> np.ndarray:
    return np.ones((n, n)) - np.eye(n)


def step(xy, state=None, t=10.0, avoidance=ONE, velocity=(20.0, 0.0, 0.0), h0=None):
    """One update for horizontal positions ``xy`` (N, 2) or (B, N, 2)."""
    xy = np.asarray(xy, dtype=float)
    if xy.ndim == 2:
        xy = xy[None]
    batch, n = xy.shape[:2]
    positions = np.concatenate([xy, np.zeros((batch, n, 1))], axis=-1)
    velocities = np.broadcast_to(np.asarray(velocity, dtype=float), positions.shape).copy()
    if state is None:
        state = init_topology(batch, n, len(avoidance.obstacles))
    h0 = ring(n) if h0 is None else h0
    return update_topology(state, positions, velocities, np.full(batch, t), avoidance, SCHEDULE, h0)


def signed_angle(u: np.ndarray, v: np.ndarray) -> float:
    """Counter-clockwise angle from u to v [rad]."""
    return math.atan2(u[0] * v[1] - u[1] * v[0], u[0] * v[0] + u[1] * v[1])


# --- preset velocity ----------------------------------------------------------------------------


def test_preset_velocity_switching_times():
    t = np.array([0.0, 50.0, 50.2, 100.0, 199.8])
    expected = [(20, 0, 0), (20, 0, 0), (0, 20, 0), (0, 20, 0), (0, -20, 0)]
    np.testing.assert_array_equal(preset_velocity(SCHEDULE, t), expected)
    assert preset_velocity(SCHEDULE, np.zeros((2, 3))).shape == (2, 3, 3)
    np.testing.assert_array_equal(preset_velocity(SCHEDULE, 150.0), (-20, 0, 0))
    # t = 250 dt accumulated in floating point still counts as t <= 50
    t_sum = sum([0.2] * 250)
    assert t_sum != 50.0
    np.testing.assert_array_equal(preset_velocity(SCHEDULE, t_sum), (20, 0, 0))


# --- geometry -----------------------------------------------------------------------------------


def test_in_range_strip_and_not_yet_abreast():
    points = np.array(
        [
            (-50.0, 0.0),  # on the centre line, ahead of the obstacle: in
            (-50.0, 39.9),  # inside the strip: in
            (-50.0, -39.9),
            (-50.0, 40.0),  # on the tangent line: out (strict)
            (-50.0, -45.0),
            (0.0, 10.0),  # abreast: out
            (10.0, 0.0),  # past: out
            (-500.0, 10.0),  # far but in the strip: in (distance plays no role)
        ]
    )
    expected = [True, True, True, False, False, False, False, True]
    positions = np.concatenate([points, np.zeros((len(points), 1))], axis=1)[None]
    e_hat, _ = heading_frame(preset_velocity(SCHEDULE, np.array([10.0])))
    centres = np.zeros((1, 2))
    _, _, dist, lon, lat = relative_geometry(positions, centres, e_hat)
    np.testing.assert_array_equal(in_range(lon, lat, R_S)[0, :, 0], expected)
    np.testing.assert_allclose(dist[0, :, 0], np.hypot(points[:, 0], points[:, 1]))
    np.testing.assert_allclose(lat[0, :, 0], points[:, 1])  # n̂ = +y for ê = +x

    # after the turn at 50 s, ê = +y and n̂ = -x
    e_hat, n_hat = heading_frame(preset_velocity(SCHEDULE, np.array([60.0])))
    np.testing.assert_allclose(e_hat, [[0.0, 1.0]])
    np.testing.assert_allclose(n_hat, [[-1.0, 0.0]])
    turned = np.array([[(-30.0, -50.0, 0.0), (-50.0, 0.0, 0.0)]])
    _, _, _, lon, lat = relative_geometry(turned, centres, e_hat)
    np.testing.assert_allclose(lat[0, :, 0], [30.0, 50.0])
    np.testing.assert_array_equal(in_range(lon, lat, R_S)[0, :, 0], [True, False])


def test_obstacle_distances_horizontal_only():
    avoidance = AvoidanceConfig(
        obstacles=(ObstacleConfig((0.0, 0.0)), ObstacleConfig((300.0, 400.0)))
    )
    positions = np.array([[[3.0, 4.0, 100.0], [0.0, 0.0, -7.0], [300.0, 0.0, 0.0]]])
    dist = obstacle_distances(positions, avoidance)
    assert dist.shape == (1, 3, 2)
    np.testing.assert_allclose(dist[0], [[5.0, 495.0], [0.0, 500.0], [300.0, 400.0]])


# --- activation ---------------------------------------------------------------------------------


def test_no_activation_beyond_detection_radius():
    state, out = step([(-75.0, 0.0), (-90.0, 10.0)])  # in range, but 75 m > d^o
    assert state.status[0, 0] == IDLE and not out.activated.any()
    np.testing.assert_array_equal(out.adjacency[0], ring(2))
    np.testing.assert_allclose(out.reference_velocity[0], [PRESET, PRESET])
    state, out = step([(-D_O, 0.0), (-90.0, 10.0)])  # exactly d^o: still outside (strict)
    assert state.status[0, 0] == IDLE
    state, out = step([(-69.0, 0.0), (-90.0, 10.0)])
    assert state.status[0, 0] == ACTIVE and out.activated[0, 0]
    assert state.activation_time[0, 0] == 10.0


def test_no_activation_when_past_or_outside_the_strip():
    _, out = step([(10.0, 0.0), (5.0, 20.0)])  # close, but past the obstacle
    assert not out.activated.any()
    _, out = step([(0.0, 0.0), (-1e-9, 41.0)])  # abreast / outside the strip
    assert not out.activated.any()
    _, out = step([(-20.0, 50.0), (-30.0, -45.0)])  # close, |λ_lat| >= R_s
    assert not out.activated.any()
    # after the turn (ê = +y) a UAV west of the obstacle is beside it, one south of it ahead
    _, out = step([(-60.0, 0.0), (-60.0, 10.0)], t=60.0)
    assert not out.activated.any()
    _, out = step([(0.0, -60.0), (10.0, -70.0)], t=60.0)
    assert out.activated[0, 0]


def test_activation_is_swarm_wide():
    """One UAV in range (far) and another near (outside the strip) activate together."""
    _, out = step([(-100.0, 0.0), (-30.0, 50.0)])
    assert out.activated[0, 0]


# --- reconstruction -----------------------------------------------------------------------------


@pytest.mark.parametrize("sign", [1, -1])
def test_case1_one_group_complete_graph(sign):
    lateral = np.array([15.0, 25.0, 5.0, 35.0, 45.0])  # innermost in range: UAV 2
    xy = np.stack([np.array([-70.0, -65.0, -60.0, -80.0, -80.0]), sign * lateral], axis=1)
    state, out = step(xy)
    assert state.status[0, 0] == ACTIVE and state.case[0, 0] == 1
    np.testing.assert_array_equal(state.side[0, 0], np.full(5, sign))
    slot = 0 if sign > 0 else 1
    assert state.guide[0, 0, slot] == 2 and state.guide[0, 0, 1 - slot] == -1
    np.testing.assert_array_equal(out.adjacency[0], complete(5))
    np.testing.assert_array_equal(out.groups[0], np.zeros(5))
    assert out.avoiding[0].all()
    ref = out.reference_velocity[0]
    np.testing.assert_allclose(ref, np.broadcast_to(ref[0], ref.shape))
    np.testing.assert_allclose(np.linalg.norm(ref[0]), 20.0)
    assert ref[0, 2] == 0.0
    assert np.sign(ref[0, 1]) == sign  # passes on its own side
    assert out.active_obstacle[0] == 0


def test_case2_split_by_sign_block_adjacency():
    xy = [
        (-60.0, 0.0),  # λ_lat = 0 counts as +
        (-70.0, 20.0),
        (-70.0, -30.0),
        (-80.0, 45.0),  # + but out of range
        (-80.0, -10.0),  # innermost of the - group
    ]
    state, out = step(xy)
    assert state.case[0, 0] == 2
    side = np.array([1, 1, -1, 1, -1])
    np.testing.assert_array_equal(state.side[0, 0], side)
    np.testing.assert_array_equal(state.guide[0, 0], [0, 4])
    expected = (side[:, None] == side[None, :]) & ~np.eye(5, dtype=bool)
    np.testing.assert_array_equal(out.adjacency[0], expected.astype(float))
    plus, minus = side > 0, side < 0
    assert not out.adjacency[0][np.ix_(plus, minus)].any()
    assert not out.adjacency[0][np.ix_(minus, plus)].any()
    np.testing.assert_array_equal(out.groups[0], [0, 0, 1, 0, 1])
    ref = out.reference_velocity[0]
    assert out.avoiding[0].all()
    np.testing.assert_allclose(ref[plus], np.broadcast_to(ref[0], (3, 3)))
    np.testing.assert_allclose(ref[minus], np.broadcast_to(ref[4], (2, 3)))
    assert ref[0, 1] > 0 > ref[4, 1]  # the + group goes left, the - group right


def test_guide_is_innermost_not_euclidean_closest():
    xy = np.array([(-45.0, 30.0), (-65.0, 10.0)])
    assert np.hypot(*xy[0]) < np.hypot(*xy[1])  # UAV 0 is closer to the centre ...
    state, _ = step(xy)
    assert state.guide[0, 0, 0] == 1  # ... but UAV 1 is innermost


def test_guide_is_most_demanding_member_ahead_not_innermost():
    # along-track stretched group (the V heading +y at O2): the member ahead at nearly the same
    # lateral offset needs the larger turn, so it guides although it is not the innermost
    xy = np.array([(-80.0, 5.0), (-45.0, 6.0)])
    state, _ = step(xy)
    assert state.guide[0, 0, 0] == 1


@pytest.mark.parametrize(
    ("leader_lat", "deadband", "case", "leader_side"),
    [
        (-1.0, 2.5, 1, 1),  # on the line: joins the others, no split (deviations §6)
        (-1.0, 0.0, 2, -1),  # the sign rule of docs/model.md splits it off alone
        (-3.0, 2.5, 2, -1),  # outside the band: a real side
        (1.0, 2.5, 1, 1),  # already on the others' side
    ],
)
def test_split_deadband_keeps_a_member_on_the_centre_line(leader_lat, deadband, case, leader_side):
    avoidance = dataclasses.replace(ONE, split_deadband=deadband)
    xy = [(-60.0, leader_lat), (-70.0, 10.0), (-70.0, 11.0), (-80.0, 20.0), (-80.0, 21.0)]
    state, out = step(xy, avoidance=avoidance)
    assert state.case[0, 0] == case
    np.testing.assert_array_equal(state.side[0, 0], [leader_side, 1, 1, 1, 1])
    assert (len(np.unique(out.groups[0])) == 1) == (case == 1)


def test_split_deadband_whole_formation_on_the_line_follows_its_mean():
    avoidance = dataclasses.replace(ONE, split_deadband=2.5)
    state, _ = step([(-60.0, 1.0), (-70.0, -2.0), (-70.0, -1.5)], avoidance=avoidance)
    assert state.case[0, 0] == 1
    np.testing.assert_array_equal(state.side[0, 0], [-1, -1, -1])


def test_guide_rechosen_each_step_and_group_ends_without_members_in_range():
    # the - group has no member in range at activation: no guide, counts as ended
    state, out = step([(-60.0, 5.0), (-60.0, -50.0)])
    np.testing.assert_array_equal(state.guide[0, 0], [0, -1])
    np.testing.assert_array_equal(state.ended[0, 0], [False, True])
    assert out.avoiding[0].tolist() == [True, False]
    np.testing.assert_allclose(out.reference_velocity[0, 1], PRESET)
    # its member enters the range: it becomes the guide
    state, out = step([(-55.0, 5.0), (-55.0, -35.0)], state)
    np.testing.assert_array_equal(state.guide[0, 0], [0, 1])
    np.testing.assert_array_equal(state.ended[0, 0], [False, False])
    assert out.avoiding[0].all()

    # two + members: the guide leaves the strip, the other member (still in range) takes over
    state, _ = step([(-60.0, 5.0), (-80.0, 20.0)])
    assert state.guide[0, 0, 0] == 0
    state, out = step([(-30.0, 45.0), (-70.0, 10.0)], state)
    assert state.guide[0, 0, 0] == 1 and state.status[0, 0] == ACTIVE
    assert out.avoiding[0].all()
    # no member left in range (one abreast, one outside the strip): the group ends, restore
    state, out = step([(1.0, 45.0), (-20.0, 41.0)], state)
    assert out.restored[0, 0] and state.status[0, 0] == DONE


# --- reference velocity -------------------------------------------------------------------------


@pytest.mark.parametrize("sign", [1, -1])
def test_tangent_reference_exact(sign):
    p = np.array([-70.0, 10.0 * sign])  # D = 70.7 m: the other UAV (67 m) triggers detection
    state, out = step([p, (-60.0, 30.0 * sign)])
    assert state.guide[0, 0, 0 if sign > 0 else 1] == 0
    ref = out.reference_velocity[0]
    np.testing.assert_allclose(ref[1], ref[0])
    assert ref[0, 2] == 0.0
    np.testing.assert_allclose(np.linalg.norm(ref[0]), 20.0)
    l_hat = ref[0, :2] / 20.0
    dist = np.linalg.norm(p)
    u_los = -p / dist
    assert l_hat[0] > 0  # ahead
    # to the left of the line of sight for +, to the right for -, by exactly asin(R_s/D)
    np.testing.assert_allclose(signed_angle(u_los, l_hat), sign * math.asin(R_S / dist))
    # exactly tangent: the line p + s l passes at distance R_s from the centre
    np.testing.assert_allclose(abs(l_hat[0] * (-p[1]) - l_hat[1] * (-p[0])), R_S)


@pytest.mark.parametrize("sign", [1, -1])
def test_inside_safety_circle_forward_tangential_and_outward(sign):
    p = np.array([-20.0, 30.0 * sign])  # D = 36.06 < R_s
    state, out = step([p, (-60.0, 35.0 * sign)])
    assert state.guide[0, 0, 0 if sign > 0 else 1] == 0
    l_hat = out.reference_velocity[0, 0, :2] / 20.0
    dist = np.linalg.norm(p)
    r_hat = p / dist
    tangential = sign * np.array([r_hat[1], -r_hat[0]])  # Rot(-s 90°) r̂
    expected = tangential + (R_S - dist) / R_S * r_hat
    np.testing.assert_allclose(l_hat, expected / np.linalg.norm(expected))
    assert l_hat[0] > 0  # forward
    assert l_hat @ r_hat > 0  # outward


@settings(max_examples=200, deadline=None)
@given(
    x=st.floats(-200.0, 200.0),
    y=st.floats(-200.0, 200.0),
    sign=st.sampled_from([1, -1]),
)
def test_tangent_direction_properties(x, y, sign):
    dist = math.hypot(x, y)
    lx, ly = tangent_direction(np.array(x), np.array(y), np.array(dist), np.array(R_S), sign)
    l_hat = np.array([float(lx), float(ly)])
    np.testing.assert_allclose(np.linalg.norm(l_hat), 1.0, rtol=1e-9)
    if dist > R_S + 1e-6:
        to_centre = np.array([-x, -y])
        cross = l_hat[0] * to_centre[1] - l_hat[1] * to_centre[0]
        np.testing.assert_allclose(cross, -sign * R_S, atol=1e-6 * dist)  # tangent, own side
        assert l_hat @ to_centre > 0  # towards the tangent point, not away from it
    elif dist > 1e-6:
        r_hat = np.array([x, y]) / dist
        assert l_hat @ r_hat >= -1e-12  # never inwards
        assert sign * (l_hat[0] * r_hat[1] - l_hat[1] * r_hat[0]) > 0  # same sense as outside


def test_current_reference_speed_option():
    avoidance = AvoidanceConfig(
        obstacles=ONE.obstacles, reference_speed="current", min_reference_speed=15.0
    )
    xy = [(-60.0, 5.0), (-70.0, 20.0)]
    _, out = step(xy, avoidance=avoidance, velocity=(10.0, 0.0, 0.0))
    np.testing.assert_allclose(np.linalg.norm(out.reference_velocity[0], axis=1), 15.0)
    _, out = step(xy, avoidance=avoidance, velocity=(0.0, 24.0, 7.0))
    np.testing.assert_allclose(np.linalg.norm(out.reference_velocity[0], axis=1), 25.0)


@pytest.mark.parametrize(
    ("guide", "speed"),
    [
        # D = 70.7 m: the tangent is 26.35° off +x, cos 0.896: 20 / 0.896 = 22.31 m/s
        ((-70.0, 10.0), 22.31),
        # D = 45.3 m: 55.7° off +x, cos 0.563 < 1 / 1.4: the limit, 1.4 x 20 = 28 m/s
        ((-45.0, 5.0), 28.0),
    ],
)
def test_pace_limit_keeps_the_preset_pace_along_the_route(guide, speed):
    xy = [guide, (-60.0, 30.0)]
    _, plain = step(xy)
    paced_avoidance = dataclasses.replace(ONE, pace_limit=1.4)
    _, paced = step(xy, avoidance=paced_avoidance)
    np.testing.assert_allclose(np.linalg.norm(plain.reference_velocity[0], axis=1), 20.0)
    ref = paced.reference_velocity[0]
    np.testing.assert_allclose(np.linalg.norm(ref, axis=1), speed, rtol=2e-4)
    # the same tangent directions, only faster
    direction = ref / np.linalg.norm(ref, axis=1, keepdims=True)
    np.testing.assert_allclose(direction, plain.reference_velocity[0] / 20.0, atol=1e-12)
    if speed < 28.0:  # its part along the route is the preset speed
        np.testing.assert_allclose(ref[:, 0], 20.0)
    with pytest.raises(ValueError, match="avoidance.pace_limit"):
        dataclasses.replace(ONE, pace_limit=0.5)


# --- end and restore ----------------------------------------------------------------------------


def test_restore_after_guides_pass_abreast():
    # the paper's V shape, 10 m left of the centre line: + = {0, 1, 3}, - = {2, 4}
    xy = np.array([(-60.0, 10.0), (-70.0, 30.0), (-70.0, -10.0), (-80.0, 50.0), (-80.0, -30.0)])
    n = len(xy)
    h0 = ring(n)
    state, out = step(xy, h0=h0)
    assert out.activated[0, 0] and state.case[0, 0] == 2
    guides = state.guide[0, 0].copy()
    np.testing.assert_array_equal(guides, [0, 2])
    side = state.side[0, 0].copy()
    split_adjacency = out.adjacency[0].copy()
    seen_partial = False
    for _ in range(200):
        xy = xy + 0.2 * out.reference_velocity[0, :, :2]
        # every member stays (nearly) outside the safety circle under ideal tracking
        assert np.linalg.norm(xy, axis=1).min() >= R_S - 1.0
        state, out = step(xy, state, h0=h0)
        np.testing.assert_array_equal(state.side[0, 0], side)  # the sides never change
        if out.restored[0, 0]:
            break
        assert state.status[0, 0] == ACTIVE
        np.testing.assert_array_equal(out.adjacency[0], split_adjacency)
        done = state.ended[0, 0]
        for slot, s in enumerate((1, -1)):
            members = side == s
            assert (out.avoiding[0, members] == (not done[slot])).all()
            if done[slot]:
                # ended only once no member is in range (abreast or outside the strip)
                in_strip = (np.abs(xy[members, 1]) < R_S) & (xy[members, 0] < 0.0)
                assert not in_strip.any()
                reference = out.reference_velocity[0, members]
                np.testing.assert_allclose(reference, np.broadcast_to(PRESET, reference.shape))
        seen_partial |= bool(done.any())
    else:
        pytest.fail("no restore")
    assert seen_partial  # one group ended before the other, keeping the split graph
    assert not ((np.abs(xy[:, 1]) < R_S) & (xy[:, 0] < 0.0)).any()
    assert state.status[0, 0] == DONE and state.restore_time[0, 0] == 10.0
    np.testing.assert_array_equal(out.adjacency[0], h0)
    np.testing.assert_array_equal(out.groups[0], np.zeros(n))
    np.testing.assert_allclose(out.reference_velocity[0], np.broadcast_to(PRESET, (n, 3)))
    assert not out.avoiding.any() and out.active_obstacle[0] == -1
    # done is final: nothing happens again, even back in front of the obstacle
    state, out = step(xy - [100.0, 0.0], state, h0=h0)
    assert state.status[0, 0] == DONE
    assert not out.activated.any() and not out.restored.any()
    np.testing.assert_array_equal(out.adjacency[0], h0)


def test_only_one_obstacle_active_at_a_time():
    avoidance = AvoidanceConfig(
        obstacles=(ObstacleConfig((0.0, 0.0)), ObstacleConfig((0.0, 150.0)))
    )
    a, b = (-50.0, 0.0), (-45.0, 150.0)  # each in range of one obstacle; b is nearer to its own
    state, out = step([a, b], avoidance=avoidance)
    np.testing.assert_array_equal(state.status[0], [IDLE, ACTIVE])
    np.testing.assert_array_equal(out.activated[0], [False, True])
    assert out.active_obstacle[0] == 1
    state, out = step([a, b], state, avoidance=avoidance)
    np.testing.assert_array_equal(state.status[0], [IDLE, ACTIVE])
    assert not out.activated.any()
    state, out = step([a, (5.0, 150.0)], state, avoidance=avoidance)  # b's guide abreast
    np.testing.assert_array_equal(state.status[0], [IDLE, DONE])
    np.testing.assert_array_equal(out.restored[0], [False, True])
    assert not out.activated.any()  # the waiting obstacle starts at the next update
    state, out = step([a, (5.0, 150.0)], state, avoidance=avoidance)
    np.testing.assert_array_equal(state.status[0], [ACTIVE, DONE])
    np.testing.assert_array_equal(out.activated[0], [True, False])
    assert out.active_obstacle[0] == 0


def test_no_obstacles():
    _, out = step([(-10.0, 0.0), (0.0, 0.0)], avoidance=AvoidanceConfig(obstacles=()))
    assert out.activated.shape == (1, 0)
    np.testing.assert_array_equal(out.adjacency[0], ring(2))
    np.testing.assert_allclose(out.reference_velocity[0], [PRESET, PRESET])


# --- state handling -----------------------------------------------------------------------------


def snapshot(state: TopologyState) -> dict[str, np.ndarray]:
    return {name: getattr(state, name).copy() for name in TopologyState.__dataclass_fields__}


def assert_state_equal(state: TopologyState, expected: dict[str, np.ndarray]) -> None:
    for name, value in expected.items():
        np.testing.assert_array_equal(getattr(state, name), value, err_msg=name)


def test_reset_topology_selected_copies_only():
    xy = np.array([[(-60.0, 0.0), (-70.0, -20.0)], [(-60.0, 10.0), (-65.0, 20.0)]])
    state, _ = step(xy)
    assert (state.status[:, 0] == ACTIVE).all()
    before = snapshot(state)
    reset = reset_topology(state, np.array([True, False]))
    assert_state_equal(state, before)  # pure
    fresh = init_topology(1, 2, 1)
    for name in TopologyState.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(reset, name)[0], getattr(fresh, name)[0])
        np.testing.assert_array_equal(getattr(reset, name)[1], before[name][1])
    state, out = step(xy, reset)  # the reset copy activates again
    assert out.activated[:, 0].tolist() == [True, False]


def test_update_is_pure():
    xy = np.array([(-60.0, 0.0), (-70.0, -20.0), (-70.0, 20.0)])
    state, _ = step(xy)
    before = snapshot(state)
    positions = np.concatenate([xy + [30.0, 0.0], np.zeros((3, 1))], axis=1)[None]
    kept = positions.copy()
    new_state, _ = update_topology(
        state, positions, np.zeros_like(positions), np.array([10.0]), ONE, SCHEDULE, ring(3)
    )
    assert_state_equal(state, before)
    np.testing.assert_array_equal(positions, kept)
    new_state.status[...] = DONE  # the new state shares no memory with the old one
    assert_state_equal(state, before)


def test_batch_equals_single_copies():
    """B copies in one call give exactly what B separate calls give."""
    rng = np.random.default_rng(0)
    avoidance = AvoidanceConfig(
        obstacles=(ObstacleConfig((0.0, 0.0)), ObstacleConfig((160.0, 30.0), 25.0))
    )
    batch, n = 12, 5
    offsets = np.array([(0.0, 0.0), (-10.0, 20.0), (-10.0, -20.0), (-20.0, 40.0), (-20.0, -40.0)])
    centre = np.stack([rng.uniform(-140.0, -70.0, batch), rng.uniform(-60.0, 60.0, batch)], 1)
    xy = centre[:, None, :] + offsets + rng.uniform(-3.0, 3.0, (batch, n, 2))
    h0 = ring(n)
    batched = init_topology(batch, n, 2)
    singles = [init_topology(1, n, 2) for _ in range(batch)]
    events = 0
    for _ in range(70):
        batched, out = step(xy, batched, avoidance=avoidance, h0=h0)
        for b in range(batch):
            singles[b], one = step(xy[b], singles[b], avoidance=avoidance, h0=h0)
            for name in TopologyState.__dataclass_fields__:
                np.testing.assert_array_equal(
                    getattr(batched, name)[b], getattr(singles[b], name)[0], err_msg=name
                )
            for name in (
                "adjacency",
                "groups",
                "reference_velocity",
                "avoiding",
                "activated",
                "restored",
                "active_obstacle",
            ):
                np.testing.assert_array_equal(
                    getattr(out, name)[b], getattr(one, name)[0], err_msg=name
                )
        events += int(out.activated.sum() + out.restored.sum())
        xy = xy + 0.5 * out.reference_velocity[:, :, :2]
    assert events >= batch  # the copies did meet obstacles


# --- preview ------------------------------------------------------------------------------------


def test_reference_preview_holds_avoiding_and_previews_schedule():
    now = np.array(
        [
            [[5.0, 6.0, 0.0], [20.0, 0.0, 0.0], [1.0, 2.0, 3.0]],
            [[7.0, 8.0, 0.0], [20.0, 0.0, 0.0], [20.0, 0.0, 0.0]],
        ]
    )
    avoiding = np.array([[True, False, False], [False, False, True]])
    preview = reference_preview(SCHEDULE, np.array([49.6, 10.0]), 0.2, 5, now, avoiding)
    assert preview.shape == (2, 3, 6, 3)
    np.testing.assert_array_equal(preview[0, 0], np.broadcast_to(now[0, 0], (6, 3)))
    np.testing.assert_array_equal(preview[1, 2], np.broadcast_to(now[1, 2], (6, 3)))
    for uav in (1, 2):  # t + kδ = 49.6 ... 50.0 | 50.2 ... 50.6
        np.testing.assert_array_equal(preview[0, uav, :3], np.broadcast_to(PRESET, (3, 3)))
        np.testing.assert_array_equal(preview[0, uav, 3:], np.broadcast_to((0, 20, 0), (3, 3)))
    np.testing.assert_array_equal(preview[1, :2], np.broadcast_to(PRESET, (2, 6, 3)))


# --- several obstacles active at once (avoidance.concurrent) ------------------------------------

# 80 m between centres is the least two 30 m obstacles may have with concurrent activation (safety
# circles apart); the one-at-a-time rule needs 140 m (detection circles apart)
PAIR = (ObstacleConfig((0.0, 0.0), 30.0), ObstacleConfig((0.0, 90.0), 30.0))
CONCURRENT = AvoidanceConfig(obstacles=PAIR, concurrent=True)
# at x = -50: lateral offsets from A (y = 0) and from B (y = 90) give the sides
#   UAV 0 (y = -10): A -, B -     UAV 1 (y = 20): A +, B -
#   UAV 2 (y = 60):  A +, B -     UAV 3 (y = 100): A +, B +
# in range of A: 0, 1; of B: 2, 3
FOUR = [(-50.0, -10.0), (-50.0, 20.0), (-50.0, 60.0), (-50.0, 100.0)]


def test_overlapping_detection_circles_need_concurrent():
    with pytest.raises(ValueError, match=r"avoidance.obstacles.*detection circles.*140\.0"):
        AvoidanceConfig(obstacles=PAIR)
    with pytest.raises(ValueError, match=r"avoidance.obstacles.*safety circles.*80\.0"):
        AvoidanceConfig(obstacles=(PAIR[0], ObstacleConfig((0.0, 79.0), 30.0)), concurrent=True)
    with pytest.raises(ValueError, match="avoidance.concurrent"):
        AvoidanceConfig(obstacles=(), concurrent="yes")


def test_concurrent_obstacles_activate_together_and_split_jointly():
    state, out = step(FOUR, avoidance=CONCURRENT)
    np.testing.assert_array_equal(state.status[0], [ACTIVE, ACTIVE])
    np.testing.assert_array_equal(out.activated[0], [True, True])
    np.testing.assert_array_equal(state.side[0], [[-1, 1, 1, 1], [-1, -1, -1, 1]])
    np.testing.assert_array_equal(state.case[0], [2, 2])
    # guides: A: + group {1, 2, 3} -> 1 (the only one in range), - group {0} -> 0;
    # B: + group {3} -> 3, - group {0, 1, 2} -> 2
    np.testing.assert_array_equal(state.guide[0], [[1, 0], [3, 2]])
    # cells of the joint split: {0}, {1, 2}, {3}: the only links are 1 <-> 2
    expected = np.zeros((4, 4))
    expected[1, 2] = expected[2, 1] = 1.0
    np.testing.assert_array_equal(out.adjacency[0], expected)
    # group id bits: 1 = side - of A, 2 = side - of B
    np.testing.assert_array_equal(out.groups[0], [3, 2, 2, 0])
    assert out.active_obstacle[0] == 0
    assert out.avoiding[0].all()


def test_concurrent_each_uav_follows_the_guided_obstacle_it_is_closest_to():
    state, out = step(FOUR, avoidance=CONCURRENT)
    xy = np.asarray(FOUR)
    centres = np.array([c.center for c in PAIR])

    def tangent(obstacle: int, guide: int, side: int) -> np.ndarray:
        rel = xy[guide] - centres[obstacle]
        lx, ly = tangent_direction(rel[0], rel[1], np.linalg.norm(rel), R_S, side)
        return 20.0 * np.array([lx, ly, 0.0])

    # clearances D - R_s: UAV 0: A 11.0, B 71.8; UAV 1: A 13.9, B 46.0; UAV 2: A 38.1, B 18.3;
    # UAV 3: A 71.8, B 11.0
    expected = [tangent(0, 0, -1), tangent(0, 1, 1), tangent(1, 2, -1), tangent(1, 3, 1)]
    np.testing.assert_allclose(out.reference_velocity[0], expected, rtol=1e-12)
    # restore one at a time: A's guides pass abreast, B stays active and keeps its split
    past_a = [(5.0, -10.0), (5.0, 20.0), (-50.0, 60.0), (-50.0, 100.0)]
    state, out = step(past_a, state, avoidance=CONCURRENT)
    np.testing.assert_array_equal(state.status[0], [DONE, ACTIVE])
    np.testing.assert_array_equal(out.restored[0], [True, False])
    expected = np.zeros((4, 4))
    expected[[0, 0, 1, 1, 2, 2], [1, 2, 0, 2, 0, 1]] = 1.0  # B's side - {0, 1, 2} is complete
    np.testing.assert_array_equal(out.adjacency[0], expected)
    np.testing.assert_array_equal(out.groups[0], [1, 1, 1, 0])
    assert out.active_obstacle[0] == 1


def test_concurrent_equals_one_at_a_time_when_obstacles_never_overlap():
    # far apart obstacles: the concurrent path gives the same outputs as the default one
    far = (ObstacleConfig((0.0, 0.0)), ObstacleConfig((0.0, 150.0)))
    rng = np.random.default_rng(3)
    xy = rng.uniform((-80.0, -60.0), (20.0, 60.0), (6, 5, 2))
    results = []
    for concurrent in (False, True):
        avoidance = AvoidanceConfig(obstacles=far, concurrent=concurrent)
        state, out = step(xy, avoidance=avoidance)
        state, out = step(xy + (30.0, 0.0), state, avoidance=avoidance)
        results.append((snapshot(state), out))
    (state_a, out_a), (state_b, out_b) = results
    for name in state_a:
        np.testing.assert_array_equal(state_a[name], state_b[name])
    for name in ("adjacency", "groups", "reference_velocity", "avoiding", "active_obstacle"):
        np.testing.assert_array_equal(getattr(out_a, name), getattr(out_b, name))
    assert out_a.avoiding.any()


@pytest.mark.parametrize("rearm", [False, True])
def test_a_done_obstacle_activates_again_only_when_rearmed(rearm):
    avoidance = dataclasses.replace(ONE, rearm=rearm)
    before, abreast = [(-50.0, 10.0), (-55.0, -15.0)], [(5.0, 10.0), (5.0, -15.0)]
    state, out = step(before, avoidance=avoidance, t=10.0)
    assert out.activated[0, 0] and state.case[0, 0] == 2
    state, out = step(abreast, state, avoidance=avoidance, t=12.0)
    assert out.restored[0, 0] and state.status[0, 0] == DONE
    # the formation comes back into range (as after a turn of the route)
    state, out = step(before, state, avoidance=avoidance, t=14.0)
    assert out.activated[0, 0] == rearm
    assert state.status[0, 0] == (ACTIVE if rearm else DONE)
    assert state.activation_time[0, 0] == (14.0 if rearm else 10.0)
    assert out.avoiding[0].all() == rearm
    if rearm:  # the split of the new activation, and its restore as the first one
        np.testing.assert_array_equal(state.side[0, 0], [1, -1])
        state, out = step(abreast, state, avoidance=avoidance, t=16.0)
        assert out.restored[0, 0] and state.restore_time[0, 0] == 16.0


# --- route return (avoidance.route_gain) --------------------------------------------------------


def test_route_correction_leads_back_to_the_preset_route():
    from uav_formation_env.core.topology import route_correction

    gain = dataclasses.replace(ONE, route_gain=0.1, route_correction_max=5.0)
    start = np.zeros((3, 3))
    t = np.array([10.0, 10.0, 10.0])  # the route point is (200, 0, 0)
    # centroids 30 m left of it, 30 m behind it and above it, 200 m right of it
    centroid = np.array([[200.0, 30.0, 0.0], [170.0, 0.0, 50.0], [200.0, -200.0, 0.0]])
    positions = centroid[:, None, :] + np.array([[5.0, 0, 0], [-5.0, 0, 0]])  # (3, 2, 3)
    c = route_correction(gain, SCHEDULE, t, positions, start)
    np.testing.assert_allclose(c, [[0.0, -3.0, 0.0], [3.0, 0.0, 0.0], [0.0, 5.0, 0.0]])
    assert route_correction(ONE, SCHEDULE, t, positions, start) is None  # the paper: off
    with pytest.raises(ValueError, match="route_start"):
        route_correction(gain, SCHEDULE, t, positions, None)
    # in the outputs: far from the obstacle every UAV gets preset + c
    state, t10, start = init_topology(1, 3, 1), np.array([10.0]), np.array([[-300.0, 0.0, 0.0]])
    far = np.array([[[-700.0, 10.0, 0.0], [-710.0, 30.0, 0.0], [-710.0, -10.0, 0.0]]])
    _, out = update_topology(state, far, far * 0, t10, gain, SCHEDULE, ring(3), route_start=start)
    expected = route_correction(gain, SCHEDULE, t10, far, start)
    assert np.abs(expected).max() > 1.0
    np.testing.assert_allclose(out.route_correction, expected)
    np.testing.assert_allclose(
        out.reference_velocity[0], np.broadcast_to(PRESET + expected, (3, 3))
    )
    # while an avoidance runs none: the group that is not guided (UAV 2, side -, no member in
    # range) keeps the preset velocity, not pulled back towards the obstacle's line
    xy = [(-50.0, 10.0), (-60.0, 30.0), (-60.0, -100.0)]
    near = np.concatenate([np.asarray(xy)[None], np.zeros((1, 3, 1))], axis=-1)
    _, out = update_topology(state, near, near * 0, t10, gain, SCHEDULE, ring(3), route_start=start)
    assert out.avoiding[0].tolist() == [True, True, False]
    np.testing.assert_array_equal(out.route_correction, 0.0)
    np.testing.assert_allclose(out.reference_velocity[0, 2], PRESET)
    assert np.linalg.norm(out.reference_velocity[0, 0]) == pytest.approx(20.0)  # the tangent
    # nor within an obstacle's detection circle, active or not (here done, not re-armed)
    done = init_topology(1, 3, 1)
    done.status[:] = DONE
    beside = np.array([[[10.0, 60.0, 0.0], [0.0, 65.0, 0.0], [-5.0, 200.0, 0.0]]])
    _, out = update_topology(
        done, beside, beside * 0, t10, gain, SCHEDULE, ring(3), route_start=start
    )
    assert not out.avoiding.any()
    np.testing.assert_array_equal(out.route_correction, 0.0)


def test_split_graph_base_keeps_h0_edges_inside_each_group():
    # the case-2 split of test_case2_split_by_sign_block_adjacency's kind, on a ring H0
    xy = [(-50.0, 10.0), (-50.0, 25.0), (-50.0, -10.0), (-50.0, -25.0)]
    h0 = ring(4)  # i receives from i + 1 (mod 4)
    _, complete = step(xy, h0=h0)
    _, base = step(xy, h0=h0, avoidance=dataclasses.replace(ONE, split_graph="base"))
    same = np.array([[0, 1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 1], [0, 0, 1, 0]], dtype=float)
    np.testing.assert_array_equal(complete.adjacency[0], same)
    # only 0 <- 1 and 2 <- 3 of the ring lie inside a group
    expected = np.zeros((4, 4))
    expected[0, 1] = expected[2, 3] = 1.0
    np.testing.assert_array_equal(base.adjacency[0], expected)
    np.testing.assert_array_equal(base.reference_velocity, complete.reference_velocity)
    with pytest.raises(ValueError, match="avoidance.split_graph"):
        dataclasses.replace(ONE, split_graph="sparse")


# --- turn preview (avoidance.turn_preview) ------------------------------------------------------

# One obstacle 60 m up the paper route's second leg (+y from the turn at (1000, 0), t = 50 s):
# along the first leg (ê = +x) it is 60 m to the side, out of range (R_s = 40 m), and at t = 47 s
# the UAVs (60 m before the turn) are 85 m from its centre, beyond d^o = 70 m. Moved to the turn
# (+3 s at 20 m/s) they are 60 m before it on the next leg and straddle that leg's centre line.
PAST_TURN = AvoidanceConfig(obstacles=(ObstacleConfig((1000.0, 60.0), 30.0),))
BEFORE_TURN = [(940.0, 5.0), (950.0, -5.0), (930.0, 5.0)]  # moved: x = 1000, 1010, 990
# Each UAV's chord runs from p to c = m + ê' (max(-λ'_lon, 0) + R_s) = (x_m, 100); by hand,
# λ^c = (p - o)·n̂_c: UAV 0: chord (60, 95), p - o = (-60, -55): 2400 / 112.36 = 21.3597 m;
# UAV 1: chord (60, 105), p - o = (-50, -65): 11.1631 m; UAV 2: chord (60, 95),
# p - o = (-70, -55): 29.8146 m. In the next leg's frame UAV 1 (x = 1010) is east of the centre.
PAST_TURN_CHORD_LAT = [21.359719655519267, 11.16312611302876, 29.814608685828976]


@pytest.mark.parametrize("preview", [0.0, 2.0, 5.0])
def test_turn_preview_activates_an_obstacle_past_the_turn_and_passes_it_inside_the_bend(preview):
    avoidance = dataclasses.replace(PAST_TURN, turn_preview=preview)
    state, out = step(BEFORE_TURN, t=47.0, avoidance=avoidance)
    active = preview >= 3.0  # the turn is 3 s away
    assert out.activated[0, 0] == active and out.avoiding[0].all() == active
    if not active:  # the paper's rule: nothing until the turn
        np.testing.assert_array_equal(out.reference_velocity[0], np.tile(PRESET, (3, 1)))
        return
    # sides from the chords: all three have the obstacle on their right (λ^c > 0), so the
    # formation passes in one group on the inside of the left turn; the next leg's frame alone
    # split UAV 1 off round the outside (side -1, case 2)
    np.testing.assert_array_equal(state.side[0, 0], [1, 1, 1])
    assert state.case[0, 0] == 1
    np.testing.assert_array_equal(out.groups[0], [0, 0, 0])
    # the group follows its guide's tangent from where the guide is now; the guide is the member
    # needing the largest turn (measured from the current heading, as for every group)
    xy = np.array(BEFORE_TURN) - (1000.0, 60.0)
    dist = np.hypot(xy[:, 0], xy[:, 1])
    lx, ly = tangent_direction(xy[:, 0], xy[:, 1], dist, R_S, 1.0)
    demand = [signed_angle(PRESET[:2], np.array([lx[i], ly[i]])) for i in range(3)]
    guide = int(np.argmax(demand))
    assert state.guide[0, 0, 0] == guide and state.guide[0, 0, 1] == -1
    for i in range(3):
        np.testing.assert_allclose(
            out.reference_velocity[0, i], [20.0 * lx[guide], 20.0 * ly[guide], 0.0], atol=1e-12
        )


def test_turn_geometry_chord_lateral_coordinates_by_hand():
    avoidance = dataclasses.replace(PAST_TURN, turn_preview=5.0)
    positions = np.concatenate([np.array(BEFORE_TURN), np.zeros((3, 1))], axis=1)[None]
    t = np.array([47.0])
    centres, r_safe, _ = obstacle_arrays(avoidance)
    preset = preset_velocity(SCHEDULE, t)
    near, dist, chord_lat, window = _turn_geometry(
        avoidance, SCHEDULE, t, positions, preset, centres, r_safe[:, None, None]
    )
    assert window.tolist() == [True]
    np.testing.assert_allclose(chord_lat[0, :, 0], PAST_TURN_CHORD_LAT, rtol=1e-12)
    # the moved positions (1000, 5), (1010, -5), (990, 5): 55, 65, 55 m before the centre on the
    # next leg, 0, 10 and 10 m beside it
    np.testing.assert_allclose(dist[0, :, 0], [55.0, np.hypot(10.0, 65.0), np.hypot(10.0, 55.0)])
    assert near[0, :, 0].all()
    # outside the window (t = 40 s: the turn is 10 s away) there is no turn geometry
    assert (
        _turn_geometry(
            avoidance, SCHEDULE, np.array([40.0]), positions, preset, centres, r_safe[:, None, None]
        )
        is None
    )


def test_turn_geometry_an_obstacle_passed_before_the_turn_keeps_the_current_legs_frame():
    # O at (950, 0), R_s = 30 m: moved to the turn, (1000, y), the UAVs are 50 m past its centre
    # along the current leg, beyond R_s, so their chords run along ê = +x and λ^c = λ_lat = y
    # (the chord to the next leg would give λ^c = -4.1, 0.0 and 11.6 m)
    avoidance = AvoidanceConfig(obstacles=(ObstacleConfig((950.0, 0.0), 20.0),), turn_preview=5.0)
    ys = np.array([-12.0, -6.0, 8.0])
    positions = np.stack([np.full(3, 940.0), ys, np.zeros(3)], axis=1)[None]
    t = np.array([47.0])
    centres, r_safe, _ = obstacle_arrays(avoidance)
    preset = preset_velocity(SCHEDULE, t)
    *_, chord_lat, window = _turn_geometry(
        avoidance, SCHEDULE, t, positions, preset, centres, r_safe[:, None, None]
    )
    assert window.tolist() == [True]
    np.testing.assert_array_equal(chord_lat[0, :, 0], ys)


# An obstacle in the corner of the same turn, 30 m past the turn point on the first leg's line
# (R_s = 30 m, d^o = 60 m), met along the current leg 1.4 s before the turn by UAVs abreast at
# y = -12, -6 and 8. The sign of λ_lat splits them (case 2: two UAVs round the outside of the
# bend, south of the obstacle); their chords to (1000, 30), (1000, 30) and (1000, 38) have
# λ^c = 41.60, 42.10 and 47.86 m by hand, so near the turn all pass on the inside.
CORNER = AvoidanceConfig(obstacles=(ObstacleConfig((1030.0, 0.0), 20.0),))
AT_CORNER = [(972.0, -12.0), (972.0, -6.0), (972.0, 8.0)]


def test_turn_preview_passes_a_corner_obstacle_on_the_inside_of_the_bend():
    state, out = step(AT_CORNER, t=48.6, avoidance=CORNER)  # the paper's rule
    assert out.activated[0, 0] and state.case[0, 0] == 2
    np.testing.assert_array_equal(state.side[0, 0], [-1, -1, 1])
    state, out = step(AT_CORNER, t=48.6, avoidance=dataclasses.replace(CORNER, turn_preview=5.0))
    assert out.activated[0, 0] and state.case[0, 0] == 1
    np.testing.assert_array_equal(state.side[0, 0], [1, 1, 1])
    assert (out.reference_velocity[0, :, 1] > 0.0).all()  # turning north, into the bend


def test_turn_preview_changes_nothing_away_from_turns():
    # t = 30 s: the turn is 20 s away (outside the window), the paper's obstacle set-up of ONE;
    # within the window the sides of any obstacle come from the chords (tests above)
    preview = dataclasses.replace(ONE, turn_preview=5.0)
    xy = [(-60.0, 10.0), (-65.0, -20.0), (-75.0, 5.0)]
    state_a, out_a = step(xy, t=30.0, avoidance=ONE)
    state_b, out_b = step(xy, t=30.0, avoidance=preview)
    assert out_a.activated.all() and out_b.activated.all()
    for field in dataclasses.fields(state_a):
        np.testing.assert_array_equal(getattr(state_a, field.name), getattr(state_b, field.name))
    np.testing.assert_array_equal(out_a.reference_velocity, out_b.reference_velocity)
    with pytest.raises(ValueError, match="avoidance.turn_preview"):
        dataclasses.replace(ONE, turn_preview=-1.0)
