"""Double-integrator UAV dynamics (docs/model.md §1): the one step used by the plant and by MPC
prediction.

State per UAV ``z = [p; v]`` with shape ``(..., 6)`` [m, m/s], z up. The acceleration ``a`` [m/s^2]
is held over the step (zero-order hold), which makes the step exact:

    p+ = p + v dt + ½ a dt²,    v+ = v + a dt.

The plant uses ``a = u + d``; the MPC prediction uses ``a = u_n`` (disturbance-free model,
docs/model.md §3.4). Array-API functions: numpy arrays or torch tensors (core/array_api.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uav_formation_env.core.array_api import is_numpy, namespace

GRAVITY = 9.81  # [m/s^2]


def zoh_increments(v: np.ndarray, a: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity change over one step with ``a`` held (the single definition).

    Args:
        v: (..., 3) velocity at the start of the step [m/s].
        a: (..., 3) held acceleration [m/s^2].
        dt: step length [s].

    Returns:
        ``(dp, dv)``, each (..., 3) [m, m/s].
    """
    dv = a * dt
    dp = (v + 0.5 * dv) * dt
    return dp, dv


def zoh_step(z: np.ndarray, a: np.ndarray, dt: float) -> np.ndarray:
    """One exact zero-order-hold step.

    Args:
        z: (..., 6) state [m, m/s].
        a: (..., 3) held acceleration [m/s^2].
        dt: step length [s].

    Returns:
        (..., 6) next state.
    """
    dp, dv = zoh_increments(z[..., 3:], a, dt)
    xp = namespace(z, a)
    if is_numpy(xp):
        # dp already has the broadcast shape and dtype of z and a; writing into one buffer
        # saves the concatenation's copy
        out = np.empty((*dp.shape[:-1], 6), dtype=dp.dtype)
        np.add(z[..., :3], dp, out=out[..., :3])
        np.add(z[..., 3:], dv, out=out[..., 3:])
        return out
    return xp.concat((z[..., :3] + dp, z[..., 3:] + dv), axis=-1)


def rollout(z0: np.ndarray, inputs: np.ndarray, dt: float) -> np.ndarray:
    """Predicted trajectories of candidate input sequences, without a loop over the horizon.

    Repeated :func:`zoh_step` written as cumulative sums of :func:`zoh_increments`, so it equals the
    step applied H times (up to floating-point summation order).

    Args:
        z0: (..., 6) initial states; broadcast against ``inputs[..., 0, :]``, e.g. (B, N, 1, 6) for
            (B, N, P, H, 3) candidates.
        inputs: (..., H, 3) input sequences [m/s^2].
        dt: step length [s].

    Returns:
        (..., H + 1, 6) states at k = 0..H (k = 0 is ``z0``).
    """
    xp = namespace(z0, inputs)
    v0 = z0[..., None, 3:]
    dv = inputs * dt
    v_after = v0 + xp.cumulative_sum(dv, axis=-2)  # v at k = 1..H
    v_before = xp.concat(
        (xp.broadcast_to(v0, v_after[..., :1, :].shape), v_after[..., :-1, :]), axis=-2
    )  # v at k = 0..H-1
    dp, _ = zoh_increments(v_before, inputs, dt)
    p_after = z0[..., None, :3] + xp.cumulative_sum(dp, axis=-2)
    future = xp.concat((p_after, v_after), axis=-1)
    start = xp.broadcast_to(z0[..., None, :], future[..., :1, :].shape)
    return xp.concat((start, future), axis=-2)


@dataclass(frozen=True)
class ForceInputs:
    """Physical inputs behind an acceleration command (docs/model.md §1.3), for reporting."""

    thrust: np.ndarray  # T [N]
    lift: np.ndarray  # L [N]
    bank: np.ndarray  # φ [rad]
    tau: np.ndarray  # (..., 3) τ = Θᵀ(u - a) [m/s^2]


def inverse_map(
    u: np.ndarray,
    v: np.ndarray,
    mass: float = 10.0,
    air_density: float = 1.225,
    wing_area: float = 0.5,
    drag_coefficient: float = 0.03,
) -> ForceInputs:
    """Thrust, lift and bank that realise the acceleration ``u`` at velocity ``v`` (eq. 2).

    ``u = Θ τ + [0, 0, -g]`` with Θ orthonormal, so ``τ = Θᵀ (u + [0, 0, g])``.
    Needs ``|v| > 0`` and ``|γ| < 90°``.

    Args:
        u: (..., 3) applied acceleration [m/s^2].
        v: (..., 3) velocity [m/s].
        mass: [kg]. air_density: [kg/m^3]. wing_area: [m^2]. drag_coefficient: C_D0 [-].

    Returns:
        :class:`ForceInputs` with arrays of shape (...).
    """
    speed = np.linalg.norm(v, axis=-1)
    chi = np.arctan2(v[..., 1], v[..., 0])
    gamma = np.arcsin(np.clip(v[..., 2] / np.maximum(speed, 1e-12), -1.0, 1.0))
    cc, sc, cg, sg = np.cos(chi), np.sin(chi), np.cos(gamma), np.sin(gamma)
    zero = np.zeros_like(chi)
    theta = np.stack(
        (
            np.stack((cc * cg, -sc, -sg * cc), axis=-1),
            np.stack((sc * cg, cc, -sg * sc), axis=-1),
            np.stack((sg, zero, cg), axis=-1),
        ),
        axis=-2,
    )
    lifted = u + np.array([0.0, 0.0, GRAVITY])
    tau = np.einsum("...ji,...j->...i", theta, lifted)
    drag = 0.5 * air_density * speed**2 * wing_area * drag_coefficient
    return ForceInputs(
        thrust=mass * tau[..., 0] + drag,
        lift=mass * np.hypot(tau[..., 1], tau[..., 2]),
        bank=np.arctan2(tau[..., 1], tau[..., 2]),
        tau=tau,
    )


def velocity_setpoint_input(
    action: np.ndarray,
    velocity: np.ndarray,
    reference: np.ndarray,
    velocity_range: float,
    gain: float,
    u_max: float,
) -> np.ndarray:
    """The formation input of the velocity action mode: a proportional loop on a set-point.

    ``u = clip(gain · (v^d + a · velocity_range - v), ±u_max)``: action 0 tracks the reference
    velocity, |a| = 1 asks for ``velocity_range`` more or less per axis.

    Args:
        action: (..., 3) normalised actions in [-1, 1].
        velocity: (..., 3) current velocities v_i [m/s].
        reference: (..., 3) current reference velocities v^d_i [m/s].
        velocity_range: set-point offset at |a| = 1 [m/s].
        gain: loop gain [1/s].
        u_max: per-axis bound [m/s^2].

    Returns:
        (..., 3) formation input u_n [m/s^2], in the arrays' library.
    """
    xp = namespace(action)
    command = gain * (reference + action * velocity_range - velocity)
    return xp.clip(command, -u_max, u_max)
