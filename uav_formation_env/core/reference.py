"""The preset velocity schedule (eq. 23) and the reference preview over the MPC horizon.

See SPEC §4.3 for the preview: the schedule at t + kδ, or the current reference held while avoiding.
"""

from __future__ import annotations

import numpy as np

from uav_formation_env.config import ScheduleConfig

__all__ = ["preset_velocity", "reference_preview"]

_TIME_TOL = 1e-9  # tolerance of the schedule's "t <= times[k]" [s]


def preset_velocity(schedule: ScheduleConfig, t: np.ndarray) -> np.ndarray:
    """Preset desired velocity of eq. 23.

    ``velocities[k]`` holds for ``times[k-1] < t <= times[k]``; t <= times[0] gives the first
    entry and t > times[-1] the last.

    Args:
        schedule: switching times and velocities.
        t: (...) time [s].

    Returns:
        (..., 3) velocity [m/s].
    """
    times = np.asarray(schedule.times, dtype=float)
    velocities = np.asarray(schedule.velocities, dtype=float).reshape(-1, 3)
    index = np.searchsorted(times, np.asarray(t, dtype=float) - _TIME_TOL, side="left")
    return velocities[index]


def reference_preview(
    schedule: ScheduleConfig,
    t: np.ndarray,
    dt: float,
    horizon: int,
    reference_now: np.ndarray,
    avoiding: np.ndarray,
) -> np.ndarray:
    """Desired velocity v^d(t + kδ) over the prediction horizon (SPEC §4.3).

    Args:
        schedule: preset velocity (eq. 23).
        t: (B,) or scalar current time [s].
        dt: control step δ [s].
        horizon: H, number of steps; k = 0..H.
        reference_now: (B, N, 3) current reference (``TopologyOutput.reference_velocity``) [m/s].
        avoiding: (B, N) bool, UAVs that hold ``reference_now`` for every k.

    Returns:
        (B, N, H+1, 3) [m/s]: the schedule at t + k·dt, except avoiding UAVs, which hold
        ``reference_now``.
    """
    reference_now = np.asarray(reference_now, dtype=float)
    batch = reference_now.shape[0]
    t = np.broadcast_to(np.asarray(t, dtype=float), (batch,))
    times = t[:, None] + dt * np.arange(horizon + 1)  # (B, H+1)
    schedule_part = preset_velocity(schedule, times)[:, None]  # (B, 1, H+1, 3)
    hold = np.asarray(avoiding, dtype=bool)[:, :, None, None]
    return np.where(hold, reference_now[:, :, None, :], schedule_part)
