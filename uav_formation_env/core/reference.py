"""The preset velocity schedule (eq. 23) and the reference preview over the MPC horizon.

See docs/model.md §4.3 for the preview: the schedule at t + kδ, or the current reference held while
avoiding.

A schedule is either one :class:`~uav_formation_env.config.ScheduleConfig` shared by every copy,
or a :class:`CopySchedules` with one (drawn) schedule per copy (scene distributions with
``scene.route``). Every function here takes both; with :class:`CopySchedules` the times ``t``
carry the copy axis first, (B, ...).

The functions take numpy arrays or torch tensors (core/array_api.py): ``t``, the other array
arguments and a :class:`CopySchedules`' arrays; a shared :class:`ScheduleConfig`'s cached numpy
arrays are converted (once, cached) to the inputs' library and device.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache, wraps
from typing import Any, TypeVar

import numpy as np

from uav_formation_env.config import ScheduleConfig
from uav_formation_env.core.array_api import (
    as_float,
    constant_like,
    device,
    is_numpy,
    namespace,
    namespace_of,
    read_only,
    take,
)
from uav_formation_env.core.tracing import is_tracing

__all__ = [
    "CopySchedules",
    "Schedule",
    "blend_offset",
    "blended_velocity",
    "config_cache",
    "copy_schedules",
    "next_leg",
    "preset_displacement",
    "preset_velocity",
    "reference_preview",
    "route_error",
    "schedule_arrays",
    "slot_route_offset",
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
        if is_tracing():  # torch.compile would replay the store with a value of its graph
            return function(config)
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
    read_only(times, velocities)
    return times, velocities


@dataclass(frozen=True)
class CopySchedules:
    """One preset schedule per copy, padded to a common number of legs.

    A copy with fewer legs repeats its last switching time (0 s if it has none) and its last
    velocity: the padding legs have zero length and every rule of eq. 23 is unchanged.

    Attributes:
        times: (B, K) switching times [s], non-decreasing along K (numpy or torch).
        velocities: (B, K+1, 3) leg velocities [m/s] (the same library and device as ``times``).
    """

    times: Any
    velocities: Any

    @property
    def batch(self) -> int:
        return self.times.shape[0]

    def set_copy(self, copy: int, schedule: ScheduleConfig) -> None:
        """Write copy ``copy``'s row (in place) from a schedule, padded as :func:`copy_schedules`
        pads (on either backend)."""
        row = copy_schedules([schedule], self.velocities.shape[1], like=self.times)
        self.times[copy], self.velocities[copy] = row.times[0], row.velocities[0]


Schedule = ScheduleConfig | CopySchedules


def copy_schedules(
    schedules: Sequence[ScheduleConfig], legs: int | None = None, like: Any = None
) -> CopySchedules:
    """Stack per-copy schedules (see :class:`CopySchedules`).

    Args:
        schedules: B schedules.
        legs: pad to this many legs (K + 1); default: the most legs of ``schedules``.
        like: an array whose library and device (and float dtype, see
            :func:`~uav_formation_env.core.array_api.float_dtype`) the arrays get; None: numpy.
    """
    most = max(len(s.velocities) for s in schedules)
    legs = most if legs is None else legs
    if legs < most:
        raise ValueError(f"legs={legs} is fewer than a schedule's {most} legs")
    times = np.empty((len(schedules), legs - 1))
    velocities = np.empty((len(schedules), legs, 3))
    for b, schedule in enumerate(schedules):
        t, v = schedule_arrays(schedule)
        times[b, : len(t)], times[b, len(t) :] = t, t[-1] if len(t) else 0.0
        velocities[b, : len(v)], velocities[b, len(v) :] = v, v[-1]
    if like is not None and not is_numpy(namespace_of(like)):
        times, velocities = as_float(times, like), as_float(velocities, like)
    return CopySchedules(times, velocities)


def _times(schedule: Schedule, t: Any) -> Any:
    """``t`` as a float array of the library and device of ``t`` or of a per-copy schedule."""
    return as_float(t, like=None if isinstance(schedule, ScheduleConfig) else schedule.times)


def _leg(schedule: Schedule, t: Any) -> tuple[Any, Any, Any]:
    """The leg index of eq. 23 at t (the number of switching times before t - tol), with the
    schedule's times and velocities broadcast against t.

    Args:
        schedule: shared or per copy.
        t: (...) float time [s], already converted by :func:`_times`.

    Returns:
        ``(index, times, velocities)``: (...) int; (..., K) [s]; (..., K+1, 3) [m/s].
    """
    if isinstance(schedule, ScheduleConfig):
        times, velocities = schedule_arrays(schedule)
        if isinstance(t, np.ndarray):
            return times.searchsorted(t - _TIME_TOL, side="left"), times, velocities
        times, velocities = constant_like(times, t), constant_like(velocities, t)
        return namespace_of(t).searchsorted(times, t - _TIME_TOL, side="left"), times, velocities
    if t.ndim == 0 or t.shape[0] != schedule.batch:
        raise ValueError(
            f"t must have the copy axis first, (B={schedule.batch}, ...), got shape "
            f"{tuple(t.shape)}"
        )
    times, velocities = schedule.times, schedule.velocities
    if not isinstance(t, np.ndarray):  # torch t: a numpy schedule moves to its device
        times, velocities = as_float(times, like=t), as_float(velocities, like=t)
    lead = (schedule.batch,) + (1,) * (t.ndim - 1)
    times = times.reshape(*lead, -1)
    velocities = velocities.reshape(*lead, -1, 3)
    # searchsorted(side="left") per copy
    index = (times < (t - _TIME_TOL)[..., None]).sum(axis=-1)
    return index, times, velocities


def _take_leg(velocities: Any, index: Any) -> Any:
    """velocities[..., index, :] per element: (K+1, 3) or (..., K+1, 3) -> (..., 3)."""
    if velocities.ndim == 2:
        return take(velocities, index, axis=0)  # a new array even for scalar t
    xp = namespace_of(velocities)
    velocities = xp.broadcast_to(velocities, (*index.shape, *velocities.shape[-2:]))
    return xp.take_along_axis(velocities, index[..., None, None], axis=-2)[..., 0, :]


def preset_velocity(schedule: Schedule, t: np.ndarray) -> np.ndarray:
    """Preset desired velocity of eq. 23.

    ``velocities[k]`` holds for ``times[k-1] < t <= times[k]``; t <= times[0] gives the first
    entry and t > times[-1] the last.

    Args:
        schedule: switching times and velocities (per copy: ``t`` is (B, ...)).
        t: (...) time [s], numpy or torch.

    Returns:
        (..., 3) velocity [m/s], in the library (and on the device) of ``t`` / the schedule.
    """
    t = as_float(t, like=None if isinstance(schedule, ScheduleConfig) else schedule.times)
    index, _, velocities = _leg(schedule, t)
    return _take_leg(velocities, index)


def next_leg(schedule: Schedule, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The preset velocity of the next leg and the time until it starts (the same leg rule as
    :func:`preset_velocity`).

    Args:
        schedule: switching times and velocities (per copy: ``t`` is (B, ...)).
        t: (...) time [s], numpy or torch.

    Returns:
        ``(velocity, wait)``: (..., 3) [m/s] and (...) [s]; on the last leg, its own velocity and
        0 s.
    """
    t = _times(schedule, t)
    xp = namespace_of(t)
    index, times, velocities = _leg(schedule, t)  # index: the current leg
    last = times.shape[-1]  # index of the last leg
    if last == 0:
        return _take_leg(velocities, index), xp.zeros(t.shape, dtype=t.dtype, device=device(t))
    if times.ndim == 1:
        switch_time = take(times, xp.minimum(index, last - 1))
    else:
        times = xp.broadcast_to(times, (*index.shape, last))
        switch_time = xp.take_along_axis(times, xp.minimum(index, last - 1)[..., None], axis=-1)
        switch_time = switch_time[..., 0]
    switch = xp.where(index < last, switch_time, t)
    return _take_leg(velocities, xp.minimum(index + 1, last)), xp.maximum(switch - t, 0.0)


def preset_displacement(schedule: Schedule, t: np.ndarray) -> np.ndarray:
    """Integral of the preset velocity (eq. 23) from 0 to t: where the preset route has gone.

    Exact for the piecewise-constant schedule: leg k holds on ``(times[k-1], times[k]]`` (leg 0
    from 0, the last leg without end), and contributes ``velocities[k]`` times the part of
    ``[0, t]`` it covers.

    Args:
        schedule: switching times and velocities (per copy: ``t`` is (B, ...)).
        t: (...) time [s], >= 0, numpy or torch.

    Returns:
        (..., 3) displacement [m].
    """
    t = _times(schedule, t)
    xp = namespace_of(t)
    _, times, velocities = _leg(schedule, t)
    t = t[..., None]  # (..., 1)
    edges = xp.maximum(times, 0.0)
    zero = xp.zeros((*edges.shape[:-1], 1), dtype=edges.dtype, device=device(edges))
    start = xp.concat((zero, edges), axis=-1)  # (..., K+1) leg k starts
    end = xp.concat((edges, zero + math.inf), axis=-1)  # (..., K+1) and ends
    covered = xp.clip(t, start, end) - start  # (..., K+1) [s]
    if velocities.ndim == 2:
        return covered @ velocities
    return (covered[..., None] * velocities).sum(axis=-2)


def blended_velocity(schedule: Schedule, t: Any, blend: float) -> Any:
    """The preset velocity averaged over a window of ``blend`` seconds centred on t.

    ``v_b(t) = (D(t + h) - D(t - h)) / (2h)``, h = blend / 2, with D the preset displacement
    (:func:`preset_displacement`, extended before t = 0 by the first leg's velocity). Far from a
    switch (more than h away) it is the preset velocity; across a switch it ramps linearly from
    one leg's velocity to the next over ``[t_s - h, t_s + h]``, so the turn starts h early and
    ends h late and the distance flown is the same: the route point is reached again at
    ``t_s + h``. A switch of eq. 23 asks for an infinite acceleration; a 90-degree turn at
    20 m/s with 5 m/s^2 per axis takes 4 s, and a formation tracking the sharp switch overshoots
    the corner by 30-60 m (docs/scenarios.md, "The shipped rules"; the drawn scenarios
    blend over 4 s). ``blend = 0`` is
    :func:`preset_velocity` itself.

    Args:
        schedule: shared or per copy (then ``t`` is (B, ...)).
        t: (...) time [s], >= 0, numpy or torch.
        blend: window length 2h [s], >= 0.

    Returns:
        (..., 3) [m/s].
    """
    if blend == 0.0:
        return preset_velocity(schedule, t)
    t = _times(schedule, t)
    xp = namespace_of(t)
    half = 0.5 * blend
    early = xp.maximum(t - half, 0.0)
    before_start = xp.maximum(half - t, 0.0)[..., None]  # the part of the window before t = 0
    first = preset_velocity(schedule, xp.zeros_like(t))
    flown = preset_displacement(schedule, t + half) - preset_displacement(schedule, early)
    return (flown + first * before_start) / blend


def blend_offset(schedule: Schedule, t: Any, blend: float) -> Any:
    """What the corner blend adds to the preset velocity now, ``v_b(t) - v^d(t)``
    (:func:`blended_velocity`): zero away from switches, and 0.0 (a float) when ``blend`` is 0.

    Args:
        schedule: shared or per copy.
        t: (...) time [s].
        blend: window [s].

    Returns:
        (..., 3) [m/s], or 0.0.
    """
    if blend == 0.0:
        return 0.0
    return blended_velocity(schedule, t, blend) - preset_velocity(schedule, t)


def route_error(
    schedule: Schedule, t: np.ndarray, centroid: np.ndarray, start: np.ndarray
) -> np.ndarray:
    """Horizontal distance of the formation centroid from the preset route.

    The preset route is ``start`` plus :func:`preset_displacement`: where the formation would be
    had it flown the preset velocity of eq. 23 exactly, without avoidance.

    Args:
        schedule: the preset velocity (per copy: ``t`` is (B, ...)).
        t: (...) time [s], broadcastable against the leading axes of ``centroid``.
        centroid: (..., 3) formation centroid [m] (numpy or torch, like the other arrays).
        start: (..., 3) centroid at t = 0 [m].

    Returns:
        (...) [m].
    """
    xp = namespace(centroid, start, t)
    if not is_numpy(xp):  # the times follow the positions' library and device
        t = as_float(t, like=centroid if is_numpy(namespace_of(t)) else t)
        start = as_float(start, like=centroid)
    route = start + preset_displacement(schedule, t)
    offset = (centroid - route)[..., :2]
    return xp.sqrt((offset**2).sum(axis=-1))


def slot_route_offset(
    schedule: Schedule,
    t: np.ndarray,
    positions: np.ndarray,
    anchored: np.ndarray,
    start: np.ndarray,
) -> np.ndarray:
    """Horizontal offset vector of each UAV from its slot on the preset route.

    UAV i's slot is where it would be with the formation centroid on the route and the others
    where they are: ``(a_i - mean_j a_j) + centroid - route(t)`` with ``a`` the positions
    relative to the formation slots (``core.cost.anchored``).

    Args:
        schedule: the preset velocity (per copy: ``t`` is (B,)).
        t: (B,) time [s].
        positions: (B, N, 3) UAV positions [m].
        anchored: (B, N, 3) positions minus formation offsets [m].
        start: (B, 3) centroid at t = 0 [m].

    Returns:
        (B, N, 2) [m]; its norm at a UAV in its slot is :func:`route_error` of the centroid.
    """
    xp = namespace(positions, start, t)
    if not is_numpy(xp):
        t = as_float(t, like=positions if is_numpy(namespace_of(t)) else t)
        start = as_float(start, like=positions)
    route = start + preset_displacement(schedule, t)
    centroid = xp.mean(positions, axis=1)
    spread = anchored - xp.mean(anchored, axis=1, keepdims=True)
    return (spread + (centroid - route)[:, None, :])[..., :2]


def reference_preview(
    schedule: Schedule,
    t: np.ndarray,
    dt: float,
    horizon: int,
    reference_now: np.ndarray,
    avoiding: np.ndarray,
    correction: np.ndarray | None = None,
) -> np.ndarray:
    """Desired velocity v^d(t + kδ) over the prediction horizon (docs/model.md §4.3).

    Args:
        schedule: preset velocity (eq. 23), shared or per copy.
        t: (B,) or scalar current time [s].
        dt: control step δ [s].
        (The arrays are numpy or torch; the result is in ``reference_now``'s library.)
        horizon: H, number of steps; k = 0..H.
        reference_now: (B, N, 3) current reference (``TopologyOutput.reference_velocity``) [m/s].
        avoiding: (B, N) bool, UAVs that hold ``reference_now`` for every k.
        correction: (B, 3) route-return term of this step, held over the horizon and added to
            the schedule (``TopologyOutput.route_correction``) [m/s]; None: none.

    Returns:
        (B, N, H+1, 3) [m/s]: the schedule at t + k·dt (plus the correction), except avoiding
        UAVs, which hold ``reference_now``.
    """
    reference_now = as_float(reference_now)
    xp = namespace_of(reference_now)
    batch = reference_now.shape[0]
    t = xp.broadcast_to(as_float(t, like=reference_now), (batch,))
    # float steps k: dt * k is the same double as numpy's dt * (int k)
    steps = xp.arange(horizon + 1, dtype=t.dtype, device=device(t))
    times = t[:, None] + dt * steps  # (B, H+1)
    schedule_part = preset_velocity(schedule, times)[:, None]  # (B, 1, H+1, 3)
    if correction is not None:
        schedule_part = schedule_part + as_float(correction, like=reference_now)[:, None, None, :]
    hold = xp.asarray(avoiding, dtype=xp.bool, device=device(reference_now))[:, :, None, None]
    return xp.where(hold, reference_now[:, :, None, :], schedule_part)
