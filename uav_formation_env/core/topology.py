"""Obstacle avoidance with topology reconstruction (docs/model.md §7), batched, on numpy arrays or
torch tensors (CPU or CUDA; core/array_api.py).

Every function here is pure: arrays with a leading batch axis B (scenario copies) in, new arrays
out; nothing is stored between calls and nothing is random. Per copy, each obstacle goes idle ->
active -> done (with ``avoidance.rearm`` a done obstacle can activate again). One
:func:`update_topology` call runs three phases: activation (an obstacle in range of the
formation activates and fixes every UAV's side), guides and ends (each side's group follows the
member that needs the largest turn, until none of its members is in range), and outputs (the
split graph H and the tangent reference v^d of the avoiding UAVs).

The full specification (geometry, tie rules, turn preview, chord sides, pace keeping, backends)
is docs/reference_policy.md, "Topology reconstruction"; docs/deviations.md says where it departs
from the paper.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

from uav_formation_env.config import AvoidanceConfig
from uav_formation_env.core.array_api import (
    amin,
    as_float,
    constant_like,
    copy,
    device,
    float_dtype,
    is_numpy,
    may_hold,
    move_batch_first,
    move_batch_last,
    namespace_of,
)
from uav_formation_env.core.obstacles import (
    ObstacleField,
    choose_sides,
    deflection_demand,
    detection_sq,
    heading_frame,
    in_range,
    obstacle_arrays,
    obstacle_distances,
    relative_geometry,
    tangent_direction,
)
from uav_formation_env.core.reference import (
    Schedule,
    blended_velocity,
    next_leg,
    preset_displacement,
    preset_velocity,
    reference_preview,
)

__all__ = [
    "ACTIVE",
    "DONE",
    "IDLE",
    "TopologyOutput",
    "TopologyState",
    "init_topology",
    "obstacle_distances",
    "preset_velocity",
    "reference_preview",
    "reset_topology",
    "route_correction",
    "update_topology",
]

IDLE, ACTIVE, DONE = 0, 1, 2
_SLOT_SIDES = np.array([1, -1], dtype=np.int8)  # side of group slot 0 and 1


@dataclass
class TopologyState:
    """Avoidance state of B scenario copies, O obstacles and N UAVs.

    The arrays are numpy arrays or torch tensors, all of one library and device.

    Attributes:
        status: (B, O) int8, 0 idle, 1 active, 2 done.
        side: (B, O, N) int8, +1 / -1 group side of each UAV, fixed at activation (0 when idle).
        guide: (B, O, 2) int64, guide UAV index of the + (slot 0) and - (slot 1) group, -1 if none.
        ended: (B, O, 2) bool, group finished its avoidance (or has no guide, see module doc).
        case: (B, O) int8, 0 none, 1 case 1 (one group), 2 case 2 (split).
        activation_time: (B, O) float, time of activation [s], NaN if never activated.
        restore_time: (B, O) float, time of the restore [s], NaN if not restored.
    """

    status: Any
    side: Any
    guide: Any
    ended: Any
    case: Any
    activation_time: Any
    restore_time: Any


@dataclass
class TopologyOutput:
    """What one :func:`update_topology` call hands to the controller (arrays of the inputs' library
    and device).

    Attributes:
        adjacency: (B, N, N) float, H at this step (row = receiver), zero diagonal.
        groups: (B, N) int64, sub-formation id: 0 when not split; in case 2, 0 = side +1 and
            1 = side -1.
        reference_velocity: (B, N, 3) desired velocity v^d of each UAV now [m/s].
        avoiding: (B, N) bool, UAV follows an avoidance reference (hold it over the horizon).
        activated: (B, O) bool, obstacle became active at this update.
        restored: (B, O) bool, obstacle finished (H <- H0) at this update.
        active_obstacle: (B,) int64, index of the active obstacle, -1 if none.
        route_correction: (B, 3) route-return term in the references of the UAVs that are not
            avoiding (:func:`route_correction`; zeros when off) [m/s].
    """

    adjacency: Any
    groups: Any
    reference_velocity: Any
    avoiding: Any
    activated: Any
    restored: Any
    active_obstacle: Any
    route_correction: Any


def init_topology(batch: int, n_uav: int, n_obstacles: int, like: Any = None) -> TopologyState:
    """All obstacles idle in every copy.

    Args:
        batch: B, number of scenario copies.
        n_uav: N, UAVs per copy.
        n_obstacles: O, obstacles per copy.
        like: an array whose library and device the state gets (the times in its float dtype,
            :func:`~uav_formation_env.core.array_api.float_dtype`); None: numpy.

    Returns:
        The initial state.
    """
    xp, at = (np, "cpu") if like is None else (namespace_of(like), device(like))
    times = float_dtype(like)
    return TopologyState(
        status=xp.zeros((batch, n_obstacles), dtype=xp.int8, device=at),
        side=xp.zeros((batch, n_obstacles, n_uav), dtype=xp.int8, device=at),
        guide=xp.full((batch, n_obstacles, 2), -1, dtype=xp.int64, device=at),
        ended=xp.zeros((batch, n_obstacles, 2), dtype=xp.bool, device=at),
        case=xp.zeros((batch, n_obstacles), dtype=xp.int8, device=at),
        activation_time=xp.full((batch, n_obstacles), math.nan, dtype=times, device=at),
        restore_time=xp.full((batch, n_obstacles), math.nan, dtype=times, device=at),
    )


def reset_topology(state: TopologyState, mask: Any) -> TopologyState:
    """Put the copies selected by ``mask`` back to the initial (all idle) state.

    Args:
        state: current state (not modified), numpy or torch.
        mask: (B,) bool, copies to reset (numpy or the state's library).

    Returns:
        New state; unselected copies are unchanged.
    """
    batch, n_obstacles, n_uav = state.side.shape
    fresh = init_topology(batch, n_uav, n_obstacles, like=state.activation_time)
    xp = namespace_of(state.status)
    m = xp.asarray(mask, dtype=xp.bool, device=device(state.status)).reshape(batch)
    fields = {}
    for name in TopologyState.__dataclass_fields__:
        old, new = getattr(state, name), getattr(fresh, name)
        fields[name] = xp.where(m.reshape((batch,) + (1,) * (old.ndim - 1)), new, old)
    return TopologyState(**fields)


def _copy_state(state: TopologyState) -> TopologyState:
    # one type test for the seven fields (not the shim's copy() per field)
    clone = np.ndarray.copy if isinstance(state.status, np.ndarray) else copy
    return TopologyState(*(clone(getattr(state, name)) for name in _STATE_FIELDS))


_STATE_FIELDS = tuple(TopologyState.__dataclass_fields__)
_CHORD_EPS = 1e-9  # a chord shorter than this has no direction [m]


def update_topology(
    state: TopologyState,
    positions: Any,
    velocities: Any,
    t: Any,
    avoidance: AvoidanceConfig,
    schedule: Schedule,
    base_adjacency: Any,
    obstacles: ObstacleField | None = None,
    route_start: Any | None = None,
) -> tuple[TopologyState, TopologyOutput]:
    """One topology update (activation, guides and ends, outputs; see the module docstring).

    Internally everything is computed batch-last ((O, N, B), (O, 2, B), ...), because numpy
    reduces short trailing axes slowly; the returned state arrays have the documented batch-first
    shapes (they are transposed views of fresh batch-last arrays, never shared with ``state``).

    The arrays are numpy arrays or torch tensors: the library (and device) of ``positions`` is
    the one of the results; with torch positions, numpy ``t``, ``base_adjacency`` and
    ``route_start`` are converted, while ``state``, ``obstacles`` and a :class:`CopySchedules`
    must already be tensors on that device.

    Args:
        state: current state (not modified).
        positions: (B, N, 3) UAV positions [m].
        velocities: (B, N, 3) UAV velocities [m/s] (used by ``reference_speed="current"``).
        t: (B,) or scalar current time [s].
        avoidance: obstacles, margins and the reference-speed rule.
        schedule: preset velocity (eq. 23), shared or per copy.
        base_adjacency: (N, N) H0 shared by every copy, or (B, N, N) per copy; row = receiver.
        obstacles: per-copy obstacles (scene distributions); None: ``avoidance.obstacles`` in
            every copy. The margins and rules always come from ``avoidance``.
        route_start: (B, 3) formation centroid at t = 0 [m], where the preset route starts;
            needed by ``avoidance.route_gain`` > 0 (:func:`route_correction`).

    Returns:
        The new state and this step's outputs.
    """
    xp = namespace_of(positions)
    positions, velocities, t, h0 = _checked_inputs(
        xp, state, positions, velocities, t, base_adjacency, avoidance, obstacles
    )
    batch, n_uav = positions.shape[:2]
    n_obs = state.status.shape[1]
    preset = preset_velocity(schedule, t)  # (B, 3): the track frame and the turn window
    # the reference outside an avoidance: the preset velocity, its corners blended, plus the
    # route return
    blend = avoidance.turn_blend
    smooth = preset if blend == 0.0 else blended_velocity(schedule, t, blend)
    correction = route_correction(avoidance, schedule, t, positions, route_start)  # (B, 3)
    base = smooth if correction is None else smooth + correction
    if n_obs == 0:
        return state, _idle_output(xp, base, h0, batch, n_uav, n_obs, correction)

    field = _field_arrays(xp, avoidance, obstacles, positions)
    centres, r_safe, r_detect_sq, present, fast_centres, r_safe_b, r_detect_b = field
    turn = _turn_geometry(avoidance, schedule, t, positions, preset, centres, r_safe_b)
    if turn is None and not may_hold(state.status == ACTIVE):
        # Fast exit for most steps: nothing active and no UAV within any idle obstacle's
        # detection radius, so nothing can activate (activation needs min_i D_i < d^o).
        rel = positions[:, :, None, :2] - fast_centres
        armed = _armed(state.status, avoidance.rearm)
        # (B, O); padding is far
        detected = amin((rel**2).sum(axis=-1), axis=1) < r_detect_sq
        if not may_hold(detected & armed):
            if correction is not None and may_hold(detected):  # see the route return below
                correction = xp.where(detected.any(axis=1)[:, None], 0.0, correction)
                base = smooth + correction
            return _copy_state(state), _idle_output(xp, base, h0, batch, n_uav, n_obs, correction)
    e_hat, _ = heading_frame(preset)
    rel_x, rel_y, dist, lon, lat = relative_geometry(positions, centres, e_hat)  # (O, N, B)
    near = in_range(lon, lat, r_safe_b)
    if turn is not None:  # in range along the next leg, from the positions at the turn
        near_turn, dist_turn, chord_lat, window = turn

    status = move_batch_last(state.status)  # (O, B)
    side = move_batch_last(state.side)  # (O, N, B)
    guide = move_batch_last(state.guide)  # (O, 2, B)
    ended = move_batch_last(state.ended)  # (O, 2, B)
    case = move_batch_last(state.case)  # (O, B)
    activation_time = move_batch_last(state.activation_time)
    restore_time = move_batch_last(state.restore_time)

    # 1. activation
    min_dist = amin(dist, axis=1)  # (O, B)
    candidate = near.any(axis=1) & (min_dist < r_detect_b)
    side_lat = lat
    if turn is not None:  # also met along the next leg; near a turn, sides from the chords
        by_turn = near_turn.any(axis=1) & (amin(dist_turn, axis=1) < r_detect_b)
        candidate = candidate | by_turn
        side_lat = xp.where(window, chord_lat, lat)
    activated = _activated(xp, candidate & present, status, min_dist, avoidance, positions)
    if may_hold(activated):
        new_side, one_group = choose_sides(side_lat, avoidance.split_deadband)
        side = xp.where(activated[:, None], new_side, side)
        case = xp.astype(xp.where(activated, xp.where(one_group, 1, 2), case), xp.int8)
        guide = xp.where(activated[:, None], -1, guide)
        ended = xp.where(activated[:, None], False, ended)
        activation_time = xp.where(activated, t, activation_time)
        status = xp.where(activated, ACTIVE, status)

    # 2. guides and ends
    active = status == ACTIVE  # (O, B)
    if may_hold(active):
        # in range along the current leg or, near a turn, along the next one
        eligible = near if turn is None else near | near_turn
        geometry = (rel_x, rel_y, dist, r_safe if obstacles is None else r_safe_b, e_hat)
        guide, ended = _guides_and_ends(xp, active, side, eligible, geometry, guide, ended)
    restored = active & ended.all(axis=1)  # (O, B)
    if may_hold(restored):
        status = xp.where(restored, DONE, status)
        restore_time = xp.where(restored, t, restore_time)

    new_state = TopologyState(
        status=status.T,
        side=move_batch_first(side),
        guide=move_batch_first(guide),
        ended=move_batch_first(ended),
        case=case.T,
        activation_time=activation_time.T,
        restore_time=restore_time.T,
    )
    if correction is not None:
        # no route return while an avoidance runs in the copy (the UAVs that are not guided, a
        # group that has passed, would be pulled back towards the obstacle's line) nor while a
        # UAV is within an obstacle's detection circle (pulled back onto the route, a formation
        # can meet the next obstacle too late to turn away)
        detected = ((min_dist < r_detect_b) & present).any(axis=0)  # (B,)
        busy = (status == ACTIVE).any(axis=0) | detected
        correction = xp.where(busy[:, None], 0.0, correction)
        base = smooth + correction
    output = _idle_output(xp, base, h0, batch, n_uav, n_obs, correction)
    output.activated = _contiguous_batch_first(activated)
    output.restored = _contiguous_batch_first(restored)
    active = status == ACTIVE
    if may_hold(active):
        geometry = (rel_x, rel_y, dist, xp.broadcast_to(r_safe_b, (n_obs, 1, batch)))
        _avoidance_output(
            output, active, side, guide, ended, case, geometry, velocities, preset, avoidance
        )
    return new_state, output


def _checked_inputs(
    xp: Any,
    state: TopologyState,
    positions: Any,
    velocities: Any,
    t: Any,
    base_adjacency: Any,
    avoidance: AvoidanceConfig,
    obstacles: ObstacleField | None,
) -> tuple[Any, Any, Any, Any]:
    """(positions, velocities, t (B,), H0) as float arrays of ``xp``; a ``ValueError`` naming
    the shapes that do not fit ``state``."""
    if is_numpy(xp):  # the conversions without the shim's calls
        positions, velocities = np.asarray(positions, dtype=float), np.asarray(velocities, float)
        t, h0 = np.asarray(t, dtype=float), np.asarray(base_adjacency, dtype=float)
    else:
        positions = as_float(positions)
        velocities, t = as_float(velocities, like=positions), as_float(t, like=positions)
        h0 = as_float(base_adjacency, like=positions)
    batch, n_uav = positions.shape[:2]
    n_obs = state.status.shape[1]
    if state.side.shape != (batch, n_obs, n_uav) or velocities.shape != positions.shape:
        raise ValueError(
            f"shape mismatch: state side {tuple(state.side.shape)}, positions "
            f"{tuple(positions.shape)}, velocities {tuple(velocities.shape)}"
        )
    n_config = len(avoidance.obstacles) if obstacles is None else obstacles.count
    if n_obs != n_config:
        raise ValueError(f"state has {n_obs} obstacles, the obstacle field has {n_config}")
    if t.shape != (batch,):
        t = xp.broadcast_to(t, (batch,))
    return positions, velocities, t, h0


def _field_arrays(
    xp: Any, avoidance: AvoidanceConfig, obstacles: ObstacleField | None, positions: Any
) -> tuple[Any, ...]:
    """(centres, r_safe, r_detect², present, centres for the fast exit, r_safe and r_detect
    batch-last): one field for every copy ((O,) radii broadcast as (O, 1, 1)) or per copy
    ((O, 1, B) and (O, B))."""
    if obstacles is None:
        centres, r_safe, r_detect = obstacle_arrays(avoidance)
        r_detect_sq, present = detection_sq(avoidance), True
        if not is_numpy(xp):  # the cached numpy constants on the positions' device
            fixed = (centres, r_safe, r_detect, r_detect_sq)
            centres, r_safe, r_detect, r_detect_sq = (constant_like(c, positions) for c in fixed)
        return (
            centres,
            r_safe,
            r_detect_sq,
            present,
            centres,
            r_safe[:, None, None],
            r_detect[:, None],
        )
    centres, r_detect_sq = obstacles.centres, obstacles.r_detect**2
    r_safe_b = obstacles.r_safe.T[:, None, :]
    return (
        centres,
        None,
        r_detect_sq,
        obstacles.present.T,
        centres[:, None],
        r_safe_b,
        obstacles.r_detect.T,
    )


def _activated(
    xp: Any, candidate: Any, status: Any, min_dist: Any, avoidance: AvoidanceConfig, like: Any
) -> Any:
    """(O, B) the obstacles that activate: every armed candidate when ``concurrent``; else at
    most one per copy, none in a busy copy, the nearest candidate (ties: lowest index)."""
    candidate = candidate & _armed(status, avoidance.rearm)
    if avoidance.concurrent:
        return candidate
    candidate &= ~(status == ACTIVE).any(axis=0)  # a busy copy waits
    chosen = _first_argmin(xp.where(candidate, min_dist, math.inf), axis=0)  # (B,)
    obs_index = xp.arange(status.shape[0], device=device(like))[:, None]
    return candidate & (obs_index == chosen)  # (O, B)


def _guides_and_ends(
    xp: Any,
    active: Any,
    side: Any,
    eligible: Any,
    geometry: tuple[Any, ...],
    guide: Any,
    ended: Any,
) -> tuple[Any, Any]:
    """Each active obstacle's group guides, re-chosen every step: the eligible (in-range)
    member needing the largest deflection; a group without one has ended. (O, 2, B) each.
    Every member's turn is measured from the current heading (one frame: measured from
    different headings, the turns of two members are not comparable)."""
    rel_x, rel_y, dist, r_safe, e_hat = geometry
    slot_sides = constant_like(_SLOT_SIDES, dist)
    member = side[:, None] == slot_sides[:, None, None]  # (O, 2, N, B)
    eligible = member & eligible[:, None]
    demand = deflection_demand(rel_x, rel_y, dist, r_safe, e_hat, slot_sides)  # (O, 2, N, B)
    best = _first_argmin(xp.where(eligible, -demand, math.inf), axis=2)  # (O, 2, B)
    has_guide = eligible.any(axis=2)
    guide = xp.where(active[:, None], xp.where(has_guide, best, -1), guide)
    ended = xp.where(active[:, None], ~has_guide, ended)
    return guide, ended


def _turn_geometry(
    avoidance: AvoidanceConfig,
    schedule: Schedule,
    t: Any,
    positions: Any,
    preset: Any,
    centres: Any,
    r_safe: Any,
) -> tuple[Any, Any, Any, Any] | None:
    """The range test along the next leg of the route, and the chord frame that sides take, for
    copies within ``avoidance.turn_preview`` of a turn; None when off or no copy is that close to
    one.

    Each UAV is moved to where it will be at the switch had it flown the preset velocity,
    m = p + v^d (t_switch - t), and judged in the next leg's track frame (ê', λ'): an obstacle just
    past a turn is out of range along the current leg until the turn, when the formation, still
    flying the old leg at 20 m/s, has no room left to avoid it (docs/scenarios.md, turn preview).

    Sides near a turn come from each UAV's *chord*: the line from p to the point of the next leg
    abreast of the far edge of the obstacle's safety circle, c = m + ê' (max(-λ'_lon, 0) + R_s),
    the way the UAV would cut the corner. λ^c = (p - o)·n̂_c, with n̂_c the chord's direction
    rotated +90°, is then used as λ_lat. Judged along either leg alone, an obstacle in the corner
    sends (part of) the formation round the outside of the bend, and it loops back to the next
    leg far behind the route point (docs/scenarios.md).

    Args:
        avoidance: ``turn_preview`` [s].
        schedule: preset velocity, shared or per copy.
        t: (B,) time [s].
        positions: (B, N, 3) [m].
        preset: (B, 3) preset velocity now [m/s].
        centres: (O, 2) or (B, O, 2) obstacle centres [m].
        r_safe: R_s broadcastable to (O, N, B) [m].

    Returns:
        ``(near, dist, chord_lat, window)``: the in-range flags (O, N, B) (False outside the
        window) and the distances D (O, N, B) [m] of the moved positions in the next leg's frame;
        λ^c (O, N, B) [m] (meaningful in window copies only); the copies within the window (B,).
    """
    if avoidance.turn_preview == 0.0:
        return None
    xp = namespace_of(positions)
    v_next, wait = next_leg(schedule, t)  # (B, 3), (B,)
    turning = ((v_next - preset) ** 2).sum(axis=1) > 1e-12
    window = turning & (wait > 0.0) & (wait <= avoidance.turn_preview)  # (B,)
    if not may_hold(window):
        return None
    moved = positions + preset[:, None, :] * xp.where(window, wait, 0.0)[:, None, None]
    e_next, _ = heading_frame(v_next)
    rel_x, rel_y, dist, lon, lat = relative_geometry(moved, centres, e_next)
    near = in_range(lon, lat, r_safe) & window
    # the chord c - p = (m - o) + ê' ahead - (p - o), batch-last (O, N, B)
    ahead = xp.maximum(-lon, 0.0) + r_safe
    e_now, _ = heading_frame(preset)
    now_x, now_y, _, lon_now, lat_now = relative_geometry(positions, centres, e_now)
    chord_x = rel_x + e_next[:, 0] * ahead - now_x
    chord_y = rel_y + e_next[:, 1] * ahead - now_y
    # zero only where a U-turn brings c back onto p: no direction, so λ^c = 0 there
    length = xp.maximum(xp.sqrt(chord_x**2 + chord_y**2), _CHORD_EPS)
    chord_lat = (now_y * chord_x - now_x * chord_y) / length  # (p - o)·n̂_c
    # an obstacle whose safety circle ends before the turn point is passed on the current leg:
    # its chord runs along ê, λ^c = λ_lat (the chord to the next leg would send a wide
    # formation round its inside, far off the route)
    to_turn = xp.sqrt(preset[:, 0] ** 2 + preset[:, 1] ** 2) * wait  # (m - p)·ê, (B,) [m]
    before_turn = lon_now + to_turn >= r_safe
    return near, dist, xp.where(before_turn, lat_now, chord_lat), window


def _armed(status: Any, rearm: bool) -> Any:
    """Obstacles that may activate: idle ones, and done ones with ``rearm`` (same shape as
    ``status``, bool). The done test only when rearmed."""
    armed = status == IDLE
    return armed | (status == DONE) if rearm else armed


def _contiguous_batch_first(x: Any) -> Any:
    """(K, B) -> a contiguous (B, K) copy (np.ascontiguousarray of the transpose)."""
    if isinstance(x, np.ndarray):
        return np.ascontiguousarray(x.T)
    return x.T.contiguous()


def route_correction(
    avoidance: AvoidanceConfig,
    schedule: Schedule,
    t: Any,
    positions: Any,
    route_start: Any | None,
) -> Any | None:
    """The route-return term of the reference outside an avoidance, or None when off.

    ``c = route_gain (r(t) - centroid)`` in the horizontal plane, scaled down to at most
    ``route_correction_max`` (and 0 while an obstacle is active in the copy or a UAV is within
    an obstacle's detection circle, see :func:`update_topology`), with r(t) = ``route_start``
    + the preset displacement (the point where the formation would be had it flown the schedule
    exactly; the mission's route error is ||r(t) - centroid||). It leads the formation back to
    its route after an avoidance, which the paper's velocity-tracking J_i alone never does.

    Args:
        avoidance: ``route_gain`` [1/s] and ``route_correction_max`` [m/s].
        schedule: preset velocity, shared or per copy.
        t: (B,) time [s].
        positions: (B, N, 3) [m], numpy or torch (``t`` and ``route_start`` are converted to
            its library and device).
        route_start: (B, 3) centroid at t = 0 [m].

    Returns:
        (B, 3) [m/s] with a zero z component, or None if ``route_gain`` is 0.
    """
    if avoidance.route_gain == 0.0:
        return None
    if route_start is None:
        raise ValueError("avoidance.route_gain > 0 needs route_start, the centroid at t = 0")
    xp = namespace_of(positions)
    if not is_numpy(xp):
        t, route_start = as_float(t, like=positions), as_float(route_start, like=positions)
    offset = route_start + preset_displacement(schedule, t) - positions.mean(axis=1)
    correction = xp.zeros_like(offset)
    correction[:, :2] = avoidance.route_gain * offset[:, :2]
    size = xp.sqrt((correction**2).sum(axis=1, keepdims=True))
    limit = avoidance.route_correction_max
    return correction * xp.minimum(1.0, limit / xp.maximum(size, 1e-12))


def _idle_output(
    xp: ModuleType,
    reference: Any,
    h0: Any,
    batch: int,
    n_uav: int,
    n_obs: int,
    correction: Any | None = None,
) -> TopologyOutput:
    """Outputs with no active obstacle: H0, one group, the schedule's (B, 3) ``reference``
    (preset velocity plus the route correction) for every UAV; in ``reference``'s library
    ``xp``."""
    at, dtype = device(reference), reference.dtype
    # fresh arrays filled by assignment (np.broadcast_to(...).copy(), np.full: slower at small B)
    adjacency = xp.empty((batch, n_uav, n_uav), dtype=dtype, device=at)
    reference_velocity = xp.empty((batch, n_uav, 3), dtype=dtype, device=at)
    adjacency[...], reference_velocity[...] = h0, reference[:, None, :]
    active_obstacle = xp.empty(batch, dtype=xp.int64, device=at)
    active_obstacle[...] = -1
    return TopologyOutput(
        adjacency=adjacency,
        groups=xp.zeros((batch, n_uav), dtype=xp.int64, device=at),
        reference_velocity=reference_velocity,
        avoiding=xp.zeros((batch, n_uav), dtype=xp.bool, device=at),
        activated=xp.zeros((batch, n_obs), dtype=xp.bool, device=at),
        restored=xp.zeros((batch, n_obs), dtype=xp.bool, device=at),
        active_obstacle=active_obstacle,
        route_correction=(
            xp.zeros((batch, 3), dtype=dtype, device=at) if correction is None else correction
        ),
    )


def _avoidance_output(
    output: TopologyOutput,
    active: Any,
    side: Any,
    guide: Any,
    ended: Any,
    case: Any,
    geometry: tuple[Any, Any, Any, Any],
    velocities: Any,
    preset: Any,
    avoidance: AvoidanceConfig,
) -> None:
    """Fill ``output`` (in place) for the copies with at least one active obstacle.

    With several active obstacles (``avoidance.concurrent``) the sub-formations are the cells of
    the joint split: i and j stay linked iff they are on the same side of every active obstacle.
    A UAV whose group of some active obstacle is guided (guide set, not ended) follows the tangent
    of the guided obstacle it is closest to (smallest D - R_s; ties: lowest index). With one
    active obstacle this is the single-obstacle rule of the module docstring.

    Args:
        output: idle outputs of this update, modified in place.
        active: (O, B) bool.
        side, guide, ended, case: batch-last state, (O, N, B), (O, 2, B), (O, 2, B), (O, B).
        geometry: rel_x, rel_y, dist (O, N, B) [m] and R_s (O, 1, B) [m].
        velocities: (B, N, 3) [m/s].
        preset: (B, 3) preset velocity now [m/s].
        avoidance: reference-speed rule.
        (All arrays of one library and device, numpy or torch.)
    """
    rel_x, rel_y, dist, r_safe = geometry
    xp, at = namespace_of(dist), device(dist)
    n_obs, n_uav, batch = side.shape
    has_active = active.any(axis=0)  # (B,)
    minus = side < 0  # (O, N, B): member of group slot 1 of that obstacle
    # 1. H: complete inside each cell of the joint split of the active obstacles
    differ = (side[:, :, None] != side[:, None, :]) & active[:, None, None]  # (O, N, N, B)
    same = ~differ.any(axis=0) & ~xp.eye(n_uav, dtype=xp.bool, device=at)[:, :, None]
    same = xp.astype(move_batch_first(same), output.adjacency.dtype)  # (B, N, N) 0/1
    if avoidance.split_graph == "complete":
        output.adjacency = xp.where(has_active[:, None, None], same, output.adjacency)
    else:  # "base": H0's own edges inside each cell (output.adjacency holds H0 here)
        adjacency = output.adjacency
        output.adjacency = xp.where(has_active[:, None, None], adjacency * same, adjacency)
    # groups: bit r set when on side -1 of the r-th split (case 2) active obstacle of the copy
    split = active & (case == 2)  # (O, B)
    rank = xp.cumulative_sum(xp.astype(split, xp.int64), axis=0) - 1  # (O, B)
    bits = xp.where(split[:, None] & minus, 2 ** xp.maximum(rank, 0)[:, None], 0)  # (O, N, B)
    output.groups = xp.astype(_contiguous_batch_first(bits.sum(axis=0)), xp.int64)
    output.active_obstacle = xp.astype(
        xp.where(has_active, _first_argmin(xp.where(active, 0, 1), axis=0), -1), xp.int64
    )
    # 2. who follows which obstacle's guide
    follow = active[:, None] & (guide >= 0) & ~ended  # (O, 2, B)
    guided = xp.where(minus, follow[:, 1:], follow[:, :1])  # (O, N, B)
    avoiding = guided.any(axis=0)  # (N, B)
    output.avoiding = _contiguous_batch_first(avoiding)
    if not may_hold(avoiding):
        return
    clearance = xp.where(guided, dist - r_safe, math.inf)  # (O, N, B)
    chosen = _first_argmin(clearance, axis=0)  # (N, B)
    # 3. each group's tangent, then each UAV's from its chosen obstacle and group
    g = xp.maximum(guide, 0)  # (O, 2, B)
    obs_index = xp.arange(n_obs, device=at)[:, None, None]
    cols = xp.arange(batch, device=at)
    index = (obs_index, g, cols)
    slot_sides = constant_like(_SLOT_SIDES, dist)[:, None]
    lx, ly = tangent_direction(rel_x[index], rel_y[index], dist[index], r_safe, slot_sides)
    if avoidance.reference_speed == "preset":
        speed = xp.sqrt((preset**2).sum(axis=1))  # (B,), broadcast against (O, 2, B)
    else:
        g_vel = velocities[cols, g]  # (O, 2, B, 3)
        speed = xp.maximum(xp.sqrt((g_vel**2).sum(axis=3)), avoidance.min_reference_speed)
    if avoidance.pace_limit > 1.0:  # keep the route point's pace along the preset direction
        horizontal = xp.sqrt(preset[:, 0] ** 2 + preset[:, 1] ** 2)  # (B,)
        along = (lx * preset[:, 0] + ly * preset[:, 1]) / xp.maximum(horizontal, 1e-9)
        speed = speed / xp.maximum(along, 1.0 / avoidance.pace_limit)
    vx, vy = speed * lx, speed * ly  # (O, 2, B)
    uav_index = xp.arange(n_uav, device=at)[:, None]
    slot = xp.astype(minus[chosen, uav_index, cols], xp.int64)  # (N, B)
    ux, uy = vx[chosen, slot, cols].T, vy[chosen, slot, cols].T  # (B, N)
    take = output.avoiding
    reference = output.reference_velocity
    reference[..., 0] = xp.where(take, ux, reference[..., 0])
    reference[..., 1] = xp.where(take, uy, reference[..., 1])
    reference[..., 2] = xp.where(take, 0.0, reference[..., 2])


def _first_argmin(values: Any, axis: int) -> Any:
    """Index of the first minimum along a (short, non-trailing) axis (numpy or torch).

    Equivalent to ``values.argmin(axis)``, but built from reductions, which numpy runs fast over
    leading axes (``argmin`` always copies the axis to the end first).
    """
    xp = namespace_of(values)
    low = amin(values, axis=axis, keepdims=True)
    shape = [1] * values.ndim
    shape[axis] = values.shape[axis]
    index = xp.arange(values.shape[axis], device=device(values)).reshape(tuple(shape))
    return amin(xp.where(values == low, index, values.shape[axis]), axis=axis)
