"""Tests of the double-integrator plant (docs/model.md §1): ZOH step, batched rollout, inverse
map."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uav_formation_env.core.dynamics import GRAVITY, inverse_map, rollout, zoh_increments, zoh_step


def theta_matrix(v: np.ndarray) -> np.ndarray:
    """Θ of docs/model.md §1.2 built independently of the module, for one velocity (3,)."""
    speed = float(np.linalg.norm(v))
    chi = math.atan2(v[1], v[0])
    gamma = math.asin(v[2] / speed)
    cc, sc, cg, sg = math.cos(chi), math.sin(chi), math.cos(gamma), math.sin(gamma)
    return np.array(
        [
            [cc * cg, -sc, -sg * cc],
            [sc * cg, cc, -sg * sc],
            [sg, 0.0, cg],
        ]
    )


# ------------------------------------------------------------------------------------------------
# zoh_step
# ------------------------------------------------------------------------------------------------


def test_zoh_step_hand_numbers_exact_binary() -> None:
    # dt = 0.5 and these numbers are exact in binary floating point.
    z = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    a = np.array([0.5, -1.0, 2.0])
    # p+ = p + v dt + 0.5 a dt^2 ; v+ = v + a dt
    expected = np.array(
        [
            1.0 + 4.0 * 0.5 + 0.5 * 0.5 * 0.25,  # 3.0625
            2.0 + 5.0 * 0.5 + 0.5 * -1.0 * 0.25,  # 4.375
            3.0 + 6.0 * 0.5 + 0.5 * 2.0 * 0.25,  # 6.25
            4.0 + 0.5 * 0.5,  # 4.25
            5.0 - 1.0 * 0.5,  # 4.5
            6.0 + 2.0 * 0.5,  # 7.0
        ]
    )
    assert expected.tolist() == [3.0625, 4.375, 6.25, 4.25, 4.5, 7.0]
    np.testing.assert_array_equal(zoh_step(z, a, 0.5), expected)


def test_zoh_step_hand_numbers_paper_dt() -> None:
    z = np.array([100.0, -20.0, 5.0, 20.0, 0.0, -1.0])
    a = np.array([0.3, -4.0, 1.5])
    dt = 0.2
    expected = np.array(
        [
            100.0 + 20.0 * 0.2 + 0.5 * 0.3 * 0.04,  # 104.006
            -20.0 + 0.0 * 0.2 + 0.5 * -4.0 * 0.04,  # -20.08
            5.0 + -1.0 * 0.2 + 0.5 * 1.5 * 0.04,  # 4.83
            20.0 + 0.3 * 0.2,  # 20.06
            0.0 - 4.0 * 0.2,  # -0.8
            -1.0 + 1.5 * 0.2,  # -0.7
        ]
    )
    np.testing.assert_allclose(expected, [104.006, -20.08, 4.83, 20.06, -0.8, -0.7], rtol=1e-14)
    np.testing.assert_allclose(zoh_step(z, a, dt), expected, rtol=1e-14, atol=1e-14)


def test_zoh_increments_match_step() -> None:
    rng = np.random.default_rng(11)
    z = rng.normal(size=(4, 6))
    a = rng.normal(size=(4, 3))
    dp, dv = zoh_increments(z[:, 3:], a, 0.2)
    nxt = zoh_step(z, a, 0.2)
    np.testing.assert_allclose(nxt[:, :3], z[:, :3] + dp, rtol=0, atol=1e-15)
    np.testing.assert_allclose(nxt[:, 3:], z[:, 3:] + dv, rtol=0, atol=1e-15)


def test_zoh_step_is_exact_solution_of_double_integrator() -> None:
    """With a held, the exact flow has the semigroup property: 20 steps of dt/20 == 1 step of dt.

    A non-exact scheme (e.g. forward Euler) fails this by O(dt^2 / 20).
    """
    rng = np.random.default_rng(5)
    z0 = np.concatenate((rng.uniform(-1e3, 1e3, (7, 3)), rng.uniform(-30, 30, (7, 3))), axis=-1)
    a = rng.uniform(-5, 5, (7, 3))
    dt = 0.2
    one = zoh_step(z0, a, dt)
    many = z0
    for _ in range(20):
        many = zoh_step(many, a, dt / 20)
    np.testing.assert_allclose(many, one, rtol=1e-12, atol=1e-10)
    # and it equals the analytic solution p(t) = p0 + v0 t + a t^2 / 2 at t = 3 dt
    three = zoh_step(zoh_step(zoh_step(z0, a, dt), a, dt), a, dt)
    t = 3 * dt
    np.testing.assert_allclose(
        three[:, :3], z0[:, :3] + z0[:, 3:] * t + 0.5 * a * t**2, rtol=1e-12, atol=1e-10
    )
    np.testing.assert_allclose(three[:, 3:], z0[:, 3:] + a * t, rtol=1e-12, atol=1e-12)
    # sanity of the check itself: forward Euler differs by 0.5 a dt^2 per step
    euler = np.concatenate((z0[:, :3] + z0[:, 3:] * dt, z0[:, 3:] + a * dt), axis=-1)
    assert np.abs(euler[:, :3] - one[:, :3]).max() > 1e-3


def test_zoh_step_does_not_mutate_inputs_and_broadcasts() -> None:
    z = np.arange(12.0).reshape(2, 6)
    a = np.array([1.0, 2.0, 3.0])  # broadcast to both UAVs
    z_copy, a_copy = z.copy(), a.copy()
    out = zoh_step(z, a, 0.1)
    np.testing.assert_array_equal(z, z_copy)
    np.testing.assert_array_equal(a, a_copy)
    assert out.shape == (2, 6)
    np.testing.assert_allclose(out[1], zoh_step(z[1], a, 0.1), rtol=0, atol=0)


# ------------------------------------------------------------------------------------------------
# rollout
# ------------------------------------------------------------------------------------------------


def _loop_rollout(z0: np.ndarray, inputs: np.ndarray, dt: float) -> np.ndarray:
    z = np.broadcast_to(z0, inputs.shape[:-2] + (6,)).copy()
    states = [z]
    for k in range(inputs.shape[-2]):
        z = zoh_step(z, inputs[..., k, :], dt)
        states.append(z)
    return np.stack(states, axis=-2)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rollout_equals_repeated_zoh_step_batched(seed: int) -> None:
    rng = np.random.default_rng(seed)
    b, n, p, h = 3, 5, 7, 6
    z0 = np.concatenate(
        (rng.uniform(-1e3, 1e3, (b, n, 1, 3)), rng.uniform(-25, 25, (b, n, 1, 3))), axis=-1
    )  # (B, N, 1, 6) broadcast over the P candidates
    inputs = rng.uniform(-5, 5, (b, n, p, h, 3))
    dt = 0.2
    traj = rollout(z0, inputs, dt)
    assert traj.shape == (b, n, p, h + 1, 6)
    # k = 0 is z0 itself (broadcast over candidates), exactly
    np.testing.assert_array_equal(traj[..., 0, :], np.broadcast_to(z0, (b, n, p, 6)))
    expected = _loop_rollout(z0, inputs, dt)
    np.testing.assert_allclose(traj, expected, rtol=1e-9, atol=1e-9)


def test_rollout_full_shape_z0_and_single_step() -> None:
    rng = np.random.default_rng(3)
    z0 = rng.normal(size=(2, 3, 4, 6))
    inputs = rng.normal(size=(2, 3, 4, 1, 3))
    traj = rollout(z0, inputs, 0.2)
    assert traj.shape == (2, 3, 4, 2, 6)
    np.testing.assert_array_equal(traj[..., 0, :], z0)
    np.testing.assert_allclose(
        traj[..., 1, :], zoh_step(z0, inputs[..., 0, :], 0.2), rtol=1e-14, atol=1e-14
    )


def test_rollout_hand_numbers() -> None:
    # one UAV, H = 2, dt = 1: p1 = 0 + 1 + 1/2 = 1.5, v1 = 2; p2 = 1.5 + 2 - 1 = 2.5, v2 = 0
    z0 = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0])
    inputs = np.array([[1.0, 0.0, 0.0], [-2.0, 0.0, 0.0]])
    traj = rollout(z0, inputs, 1.0)
    np.testing.assert_array_equal(traj[:, 0], [0.0, 1.5, 2.5])
    np.testing.assert_array_equal(traj[:, 3], [1.0, 2.0, 0.0])
    np.testing.assert_array_equal(traj[:, [1, 2, 4, 5]], 0.0)


# ------------------------------------------------------------------------------------------------
# inverse_map
# ------------------------------------------------------------------------------------------------


def test_inverse_map_level_flight() -> None:
    v = np.array([20.0, 0.0, 0.0])
    out = inverse_map(np.zeros(3), v, mass=10.0)
    drag = 0.5 * 1.225 * 20.0**2 * 0.5 * 0.03  # = 3.675 N
    assert drag == pytest.approx(3.675, rel=1e-12)
    assert float(out.bank) == pytest.approx(0.0, abs=1e-15)
    assert float(out.lift) == pytest.approx(10.0 * GRAVITY, rel=1e-14)  # L = m g
    assert float(out.thrust) == pytest.approx(drag, rel=1e-12)  # T = D: no acceleration
    np.testing.assert_allclose(out.tau, [0.0, 0.0, GRAVITY], atol=1e-14)


@pytest.mark.parametrize("a_lat", [0.5, 2.0, -3.0, 5.0])
def test_inverse_map_horizontal_turn(a_lat: float) -> None:
    m = 10.0
    out = inverse_map(np.array([0.0, a_lat, 0.0]), np.array([20.0, 0.0, 0.0]), mass=m)
    assert float(out.bank) == pytest.approx(math.atan2(a_lat, GRAVITY), rel=1e-13)
    assert float(out.lift) == pytest.approx(m * math.sqrt(a_lat**2 + GRAVITY**2), rel=1e-13)
    # no along-track acceleration: thrust only balances drag
    assert float(out.thrust) == pytest.approx(0.5 * 1.225 * 400 * 0.5 * 0.03, rel=1e-12)
    # flying north, the left (positive-bank) side is -x: same bank for u = (-a, 0, 0)
    north = inverse_map(np.array([-a_lat, 0.0, 0.0]), np.array([0.0, 20.0, 0.0]), mass=m)
    assert float(north.bank) == pytest.approx(math.atan2(a_lat, GRAVITY), rel=1e-12)


def test_inverse_map_no_drag_reports_tau_x() -> None:
    out = inverse_map(
        np.array([1.0, 0.0, 0.0]), np.array([20.0, 0.0, 0.0]), mass=4.0, air_density=0.0
    )
    assert float(out.thrust) == pytest.approx(4.0 * 1.0, rel=1e-14)


def test_inverse_map_round_trip_random() -> None:
    rng = np.random.default_rng(42)
    n = 500
    speed = rng.uniform(5.0, 40.0, n)
    chi = rng.uniform(-math.pi, math.pi, n)
    gamma = rng.uniform(-math.radians(79.9), math.radians(79.9), n)
    v = np.stack(
        (
            speed * np.cos(gamma) * np.cos(chi),
            speed * np.cos(gamma) * np.sin(chi),
            speed * np.sin(gamma),
        ),
        axis=-1,
    )
    u = rng.uniform(-5.0, 5.0, (n, 3))
    out = inverse_map(u, v, mass=10.0)
    assert out.tau.shape == (n, 3) and out.lift.shape == (n,) and out.bank.shape == (n,)
    for i in range(n):
        theta = theta_matrix(v[i])
        np.testing.assert_allclose(theta.T @ theta, np.eye(3), atol=1e-14)
        # u = Θ τ + [0, 0, -g]
        np.testing.assert_allclose(theta @ out.tau[i] + [0.0, 0.0, -GRAVITY], u[i], atol=1e-12)
    # lift and bank are the polar form of (τ_y, τ_z); thrust = m τ_x + D
    np.testing.assert_allclose(out.lift * np.sin(out.bank), 10.0 * out.tau[:, 1], atol=1e-11)
    np.testing.assert_allclose(out.lift * np.cos(out.bank), 10.0 * out.tau[:, 2], atol=1e-11)
    drag = 0.5 * 1.225 * speed**2 * 0.5 * 0.03
    np.testing.assert_allclose(out.thrust, 10.0 * out.tau[:, 0] + drag, rtol=1e-12, atol=1e-11)


def test_inverse_map_climb_is_z_up() -> None:
    # climbing at 30 deg with u = 0: τ = Θᵀ [0, 0, g] = g [sin γ, 0, cos γ] (gravity decelerates)
    gamma = math.radians(30.0)
    v = 20.0 * np.array([math.cos(gamma), 0.0, math.sin(gamma)])
    out = inverse_map(np.zeros(3), v)
    np.testing.assert_allclose(out.tau, [GRAVITY * 0.5, 0.0, GRAVITY * math.cos(gamma)], atol=1e-13)
