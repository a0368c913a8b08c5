"""The corner blend of the reference (``avoidance.turn_blend``, core/reference.py
``blended_velocity``): closed-form values on the paper's schedule, the distance flown kept, per
copy, on torch, and the reference the topology hands out."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from uav_formation_env.config import AvoidanceConfig, ObstacleConfig, ScheduleConfig
from uav_formation_env.core.reference import (
    blend_offset,
    blended_velocity,
    copy_schedules,
    preset_displacement,
    preset_velocity,
)
from uav_formation_env.core.topology import init_topology, update_topology

PAPER = ScheduleConfig()  # +x, +y, -x, -y at 20 m/s, switching at 50, 100 and 150 s


def test_blended_velocity_ramps_linearly_across_a_switch():
    t = np.array([10.0, 47.9, 48.0, 49.0, 50.0, 51.0, 52.0, 52.1, 100.0, 0.0, 1.0])
    # a 4 s window: the 90-degree turn at 50 s ramps from (20, 0) to (0, 20) over 48..52 s; by
    # hand, the window of 49 s, [47, 51], holds 3 s of +x and 1 s of +y: (15, 5); at 100 s half
    # +y, half -x; at t <= 2 s the window reaches before t = 0, where the first leg holds
    expected = [
        (20, 0),
        (20, 0),
        (20, 0),
        (15, 5),
        (10, 10),
        (5, 15),
        (0, 20),
        (0, 20),
        (-10, 10),
        (20, 0),
        (20, 0),
    ]
    got = blended_velocity(PAPER, t, 4.0)
    np.testing.assert_allclose(got[:, :2], expected, atol=1e-12)
    np.testing.assert_array_equal(got[:, 2], 0.0)


def test_the_blend_flies_the_same_distance_and_is_the_preset_velocity_when_off():
    t = np.arange(40.0, 60.0 + 1e-9, 0.01)
    v = blended_velocity(PAPER, t, 4.0)
    flown = ((v[1:] + v[:-1]) / 2 * 0.01).sum(axis=0)  # trapezoids: exact on a ramp
    np.testing.assert_allclose(
        flown, preset_displacement(PAPER, 60.0) - preset_displacement(PAPER, 40.0), atol=1e-9
    )
    np.testing.assert_array_equal(blended_velocity(PAPER, t, 0.0), preset_velocity(PAPER, t))
    assert blend_offset(PAPER, t, 0.0) == 0.0
    np.testing.assert_allclose(blend_offset(PAPER, np.array([49.0]), 4.0), [[-5.0, 5.0, 0.0]])


def test_per_copy_schedules_blend_each_copy_on_its_own_route():
    other = ScheduleConfig(times=(20.0,), velocities=((0.0, 20.0, 0.0), (20.0, 0.0, 0.0)))
    schedules = copy_schedules([PAPER, other])
    t = np.array([[19.0, 49.0], [19.0, 49.0]])
    got = blended_velocity(schedules, t, 4.0)
    np.testing.assert_allclose(got[0], blended_velocity(PAPER, t[0], 4.0), atol=1e-12)
    np.testing.assert_allclose(got[1], blended_velocity(other, t[1], 4.0), atol=1e-12)
    np.testing.assert_allclose(got[1, 0], [5.0, 15.0, 0.0], atol=1e-12)


def test_torch_blend_equals_numpy():
    torch = pytest.importorskip("torch")
    t = np.array([10.0, 49.0, 50.0, 51.5, 1.0])
    ours = blended_velocity(PAPER, torch.as_tensor(t, dtype=torch.float64), 4.0)
    assert isinstance(ours, torch.Tensor)
    np.testing.assert_allclose(ours.numpy(), blended_velocity(PAPER, t, 4.0), atol=1e-12)


def test_the_topology_hands_out_the_blended_reference_outside_an_avoidance():
    far = AvoidanceConfig(obstacles=(ObstacleConfig((5000.0, 5000.0), 30.0),))
    positions = np.zeros((1, 3, 3))
    positions[0, :, 0] = [970.0, 975.0, 980.0]
    velocities = np.zeros((1, 3, 3))
    velocities[0, :, 0] = 20.0
    h0 = np.roll(np.eye(3), 1, axis=1)
    for blend, expected in ((0.0, (20.0, 0.0, 0.0)), (4.0, (15.0, 5.0, 0.0))):
        avoidance = dataclasses.replace(far, turn_blend=blend)
        _, out = update_topology(
            init_topology(1, 3, 1), positions, velocities, np.array([49.0]), avoidance, PAPER, h0
        )
        np.testing.assert_allclose(out.reference_velocity[0], np.tile(expected, (3, 1)))
    with pytest.raises(ValueError, match="avoidance.turn_blend"):
        dataclasses.replace(far, turn_blend=-1.0)
