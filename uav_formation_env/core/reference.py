"""The preset velocity schedule (eq. 23) and the reference preview over the MPC horizon.

See docs/model.md §4.3 for the preview: the schedule at t + kδ, or the current reference held while
avoiding.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache, wraps
from typing import TypeVar

import numpy as np

from uav_formation_env.config import ScheduleConfig

__all__ = [
    "config_cache",
    "next_leg",
    "preset_displacement",
    "preset_velocity",
    "reference_preview",
    "route_error",
    "schedule_arrays",
]

_TIME_TOL = 1e-9  # tolerance of the schedule's "t <= times[k]" [s]


_Config = TypeVar("_Config")
_Value = TypeVar("_Value")


def config_cache(function: Callable[[_Config], _Value]) -> Callable[[_Config], _Value]:
    """Memoise a function of one frozen (hashable) configuration.

    ``functools.lru_cache`` alone rehashes every field of a frozen dataclass on each call, which
    for nested configurations costs more than the arrays it saves; so calls are first looked up
    by the configuration's identity (the entry holds the configuration, so its id is not reused),
    then by value. Cached results are shared: return read-only arrays.
    """
    by_value = lru_cache(maxsize=16)(function)
    by_id: dict[int, tuple[_Config, _Value]] = {}

    @wraps(function)
    def cached(config: _Config) -> _Value:
        hit = by_id.get(id(config))
        if hit is not None and hit[0] is config:
            return hit[1]
        value = by_value(config)
        if len(by_id) >= 64:
            by_id.clear()
        by_id[id(config)] = (config, value)
        return value

    return cached


@config_cache
def schedule_arrays(schedule: ScheduleConfig) -> tuple[np.ndarray, np.ndarray]:
    """Switching times (K,) [s] and velocities (K+1, 3) [m/s] of a schedule, cached, read-only.

    The preset velocity is looked up every control step; converting the config's tuples each
    time cost more than the lookup itself.
    """
    times = np.asarray(schedule.times, dtype=float)
    velocities = np.asarray(schedule.velocities, dtype=float).reshape(-1, 3)
    times.flags.writeable = False
    velocities.flags.writeable = False
    return times, velocities


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
    times, velocities = schedule_arrays(schedule)
    index = times.searchsorted(np.asarray(t, dtype=float) - _TIME_TOL, side="left")
    return velocities.take(index, axis=0)  # a new array even for scalar t


def next_leg(schedule: ScheduleConfig, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The preset velocity of the next leg and the time until it starts (the same leg rule as
    :func:`preset_velocity`).

    Args:
        schedule: switching times and velocities.
        t: (...) time [s].

    Returns:
        ``(velocity, wait)``: (..., 3) [m/s] and (...) [s]; on the last leg, its own velocity and
        0 s.
    """
    times, velocities = schedule_arrays(schedule)
    t = np.asarray(t, dtype=float)
    index = times.searchsorted(t - _TIME_TOL, side="left")  # the current leg
    last = len(times)  # index of the last leg
    if last == 0:
        return velocities.take(index, axis=0), np.zeros(t.shape)
    switch = np.where(index < last, times.take(np.minimum(index, last - 1)), t)
    return velocities.take(np.minimum(index + 1, last), axis=0), np.maximum(switch - t, 0.0)


def preset_displacement(schedule: ScheduleConfig, t: np.ndarray) -> np.ndarray:
    """Integral of the preset velocity (eq. 23) from 0 to t: where the preset route has gone.

    Exact for the piecewise-constant schedule: leg k holds on ``(times[k-1], times[k]]`` (leg 0
    from 0, the last leg without end), and contributes ``velocities[k]`` times the part of
    ``[0, t]`` it covers.

    Args:
        schedule: switching times and velocities.
        t: (...) time [s], >= 0.

    Returns:
        (..., 3) displacement [m].
    """
    times, velocities = schedule_arrays(schedule)
    t = np.asarray(t, dtype=float)[..., None]  # (..., 1)
    start = np.concatenate(([0.0], np.maximum(times, 0.0)))  # (K+1,) leg k starts
    end = np.concatenate((np.maximum(times, 0.0), [np.inf]))  # (K+1,) and ends
    covered = np.clip(t, start, end) - start  # (..., K+1) [s]
    return covered @ velocities


def route_error(
    schedule: ScheduleConfig, t: np.ndarray, centroid: np.ndarray, start: np.ndarray
) -> np.ndarray:
    """Horizontal distance of the formation centroid from the preset route.

    The preset route is ``start`` (the centroid at t = 0) plus :func:`preset_displacement`: where
    the formation would be had it flown the preset velocity of eq. 23 exactly, without avoidance.

    Args:
        schedule: the preset velocity.
        t: (...) time [s], broadcastable against the leading axes of ``centroid``.
        centroid: (..., 3) formation centroid [m].
        start: (..., 3) centroid at t = 0 [m].

    Returns:
        (...) [m].
    """
    route = start + preset_displacement(schedule, t)
    offset = (centroid - route)[..., :2]
    return np.sqrt((offset**2).sum(axis=-1))


def reference_preview(
    schedule: ScheduleConfig,
    t: np.ndarray,
    dt: float,
    horizon: int,
    reference_now: np.ndarray,
    avoiding: np.ndarray,
) -> np.ndarray:
    """Desired velocity v^d(t + kδ) over the prediction horizon (docs/model.md §4.3).

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
