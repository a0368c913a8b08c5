"""What a UAV knows: its own-frame view of the swarm and the plans its neighbours broadcast.

Pure functions behind :class:`~uav_formation_env.policies.dmpc.NashDMPCPolicy`. UAV i sees its
own velocity, reference, disturbance estimate, time and "avoiding" flag, and per other UAV j the
neighbour flag h_ij and the relative formation error ``a_j - a_i`` (``a = z - z^d``, see
:mod:`uav_formation_env.core.observation`). It never sees an absolute position, so it works in its
own frame: own position 0, own velocity as observed, ``a_j = a_i + (a_j - a_i)``. J_i depends on
anchored states only through differences, and on the own velocity, so this frame gives the same
J_i as global coordinates (up to the float32 rounding of the observation).

Plans: UAV i uses the broadcast plan of j only if h_ij = 1 in its own observation; a
non-neighbour's view is predicted with zero inputs and enters J_i only through the separation term
(every other UAV is sensed; docs/deviations.md §5). The relative position of j seen by i is the
observed relative formation error plus the mission offsets, ``p^d_j - p^d_i``.

Shapes: B copies, N UAVs (receivers i and senders j), H horizon steps. Arrays are numpy or torch
(the library and device of the decoded observations), on either observation layout.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from uav_formation_env.config import Scenario
from uav_formation_env.core import topology
from uav_formation_env.core.array_api import (
    as_float,
    asarray_like,
    constant_like,
    device,
    namespace_of,
)
from uav_formation_env.core.cost import (
    HorizonCost,
    anchored,
    prepare_horizon_cost,
    prepare_slot_horizon_cost,
    superposed_rollout,
)
from uav_formation_env.core.local_observation import DecodedLocalObservation, slot_frame
from uav_formation_env.core.observation import DecodedObservation, others_index
from uav_formation_env.core.reference import CopySchedules

__all__ = [
    "HorizonProblems",
    "OwnFrameViews",
    "horizon_problems",
    "input_half_width",
    "observed_time",
    "own_frame_views",
    "received_plans",
    "shift_warm_start",
]


def shift_warm_start(plans: np.ndarray) -> np.ndarray:
    """The warm start of eq. 20: shift a plan by one step and repeat its last entry.

    Args:
        plans: (..., H, 3) input sequences u(0..H-1 | t-δ) broadcast at the previous step [m/s^2].

    Returns:
        (..., H, 3) ``[u(1|t-δ), ..., u(H-1|t-δ), u(H-1|t-δ)]`` (a new array).
    """
    plans = as_float(plans)
    return namespace_of(plans).concat((plans[..., 1:, :], plans[..., -1:, :]), axis=-2)


def observed_time(time_fraction: np.ndarray, duration: float, dt: float) -> np.ndarray:
    """t [s] from the observed t / duration, snapped to the δ grid (the slot is float32).

    Args:
        time_fraction: (...) observed t / duration.
        duration: episode length [s].
        dt: control step δ [s].

    Returns:
        (...) ``round(t / δ) δ``, the same float the simulator computes as ``steps * δ``.
    """
    fraction = as_float(time_fraction)
    return namespace_of(fraction).round(fraction * duration / dt) * dt


# the switching times the local observation implies are snapped to this grid [s]: the float32
# slots carry about 3e-5 s of rounding at t = 200 s, which would move a switch at t = 50 s off
# the control grid; a drawn switch time lies within 5e-5 s of a grid point with p = 5e-4
SWITCH_TIME_GRID = 1e-4


def observed_schedule(decoded: DecodedLocalObservation, now: np.ndarray) -> CopySchedules:
    """Each UAV's preset schedule as far as its local observation tells: the current preset
    velocity until ``now + time_to_switch``, then the next leg's (one B·N copy per UAV).

    Enough for any preview shorter than a leg; the reference of an avoiding UAV is its tangent
    reference, which :func:`~uav_formation_env.core.reference.reference_preview` holds anyway.

    Args:
        decoded: (B, N) decoded local observations.
        now: (B·N,) each UAV's observed time [s].
    """
    xp = namespace_of(now)
    switch = xp.round((now + decoded.time_to_switch.reshape(-1)) / SWITCH_TIME_GRID)
    legs = xp.stack([decoded.reference_velocity, decoded.next_velocity], axis=-2)
    return CopySchedules(
        times=(switch * SWITCH_TIME_GRID)[:, None], velocities=legs.reshape(-1, 2, 3)
    )


@dataclass(frozen=True)
class OwnFrameViews:
    """Every receiver's picture of the swarm at time t, in its own frame.

    Attributes:
        z_own: (B, N, 6) own state: position 0, own velocity [m, m/s].
        views: (B, N_recv, N_send, 6) each sender's state as the receiver sees it (the diagonal is
            the receiver itself) [m, m/s].
        adjacency: (B, N_recv, N_send) h_ij from the receiver's own observation.
    """

    z_own: np.ndarray
    views: np.ndarray
    adjacency: np.ndarray


def own_frame_views(decoded: DecodedObservation, offsets: np.ndarray) -> OwnFrameViews:
    """Build every receiver's own-frame states from its observation alone.

    Args:
        decoded: :func:`~uav_formation_env.core.observation.decode_observations` of (B, N, dim).
        offsets: (N, 6) formation offsets z^d (mission data).
    """
    velocity = decoded.velocity
    xp, where = namespace_of(velocity), {"dtype": velocity.dtype, "device": device(velocity)}
    batch, n = velocity.shape[:2]
    offsets = asarray_like(offsets, velocity)
    rows = xp.arange(n, device=device(velocity))[:, None]
    others = constant_like(others_index(n), velocity)
    z_own = xp.concat((xp.zeros((batch, n, 3), **where), velocity), axis=-1)
    a_own = anchored(z_own, offsets)  # (B, N, 6)
    views = xp.repeat(a_own[:, :, None], n, axis=2)  # anchored, (B, N_recv, N_send, 6)
    views[:, rows, others] += decoded.relative_formation_error
    views += offsets  # states z_j = a_j + z^d_j
    adjacency = xp.zeros((batch, n, n), **where)
    adjacency[:, rows, others] = xp.astype(decoded.neighbour, velocity.dtype)
    return OwnFrameViews(z_own=z_own, views=views, adjacency=adjacency)


def received_plans(plans: np.ndarray, adjacency: np.ndarray) -> np.ndarray:
    """The sequences each receiver assumes for each sender: the sender's plan if h_ij = 1, else 0.

    Args:
        plans: (B, N_send, H, 3) sequences the senders broadcast (already shifted) [m/s^2].
        adjacency: (B, N_recv, N_send) h_ij.

    Returns:
        (B, N_recv, N_send, H, 3) [m/s^2].
    """
    return namespace_of(plans).where(adjacency[..., None, None] > 0, plans[:, None], 0.0)


@dataclass(frozen=True)
class HorizonProblems:
    """Every UAV's horizon problem at time t (leading dims (B, N)).

    Attributes:
        cost: J_i of candidates (B, N, P, H, 3) -> (B, N, P), the one definition of
            :mod:`uav_formation_env.core.cost`.
        half_width: (B, N, 3) the search box ``|u_n,c| <= u_max - |u_d,c|`` with
            ``u_d = -estimate`` (docs/model.md §1.5), at least 0 [m/s^2].
    """

    cost: HorizonCost
    half_width: np.ndarray


def received_slot_plans(
    plans: np.ndarray, neighbour_index: np.ndarray, adjacency: np.ndarray
) -> np.ndarray:
    """The sequences each receiver assumes for the UAV in each of its slots: that UAV's plan if
    h_ij = 1, else 0 (as :func:`received_plans`).

    Args:
        plans: (B, N_send, H, 3) sequences the senders broadcast [m/s^2].
        neighbour_index: (B, N_recv, k) the sender in each slot, -1 where absent.
        adjacency: (B, N_recv, k) h_ij of each slot (0 where absent).

    Returns:
        (B, N_recv, k, H, 3) [m/s^2].
    """
    xp = namespace_of(plans)
    batch = plans.shape[0]
    copies = xp.reshape(xp.arange(batch, device=device(plans)), (batch, 1, 1))
    index = neighbour_index
    index = xp.where(index > 0, index, 0)  # absent slots (-1) read row 0, masked below
    gathered = plans[copies, index]  # (B, N_recv, k, H, 3)
    return xp.where(adjacency[..., None, None] > 0, gathered, 0.0)


def horizon_problems(
    decoded: DecodedObservation | DecodedLocalObservation, plans: np.ndarray, scenario: Scenario
) -> HorizonProblems:
    """Every UAV's J_i against the plans it receives, from its observation and mission data.

    Neighbour predictions are disturbance-free ZOH rollouts
    (:func:`~uav_formation_env.core.cost.superposed_rollout`) of the senders' observed states under
    their plans; every other UAV is rolled out with zero inputs (its positions enter only the
    separation term). The reference preview is the preset schedule at t + kδ, or the UAV's current
    reference held over the horizon while its observation says "avoiding" (docs/model.md §4.3).
    The obstacle term (when ``cost.obstacle`` > 0) reads the obstacles in the observation: the
    nearest one in the full layout, the m nearest in the local one.

    Args:
        decoded: observations (B, N, dim), decoded: the full layout, or the local one
            (:func:`~uav_formation_env.core.local_observation.decode_local_observations` with
            its ``neighbour_index``), in which UAV i sees only the UAVs in its slots and works in
            their :func:`~uav_formation_env.core.local_observation.slot_frame` (the formation
            offsets then come from the observation, not the scenario).
        plans: (B, N, H, 3) each sender's sequence as receivers assume it (eq. 20 warm starts, or
            the previous inner round's outputs) [m/s^2]; only neighbours' rows are used.
        scenario: mission data: offsets, weights, horizon, δ, duration, u_max, schedule.
    """
    dt, horizon = scenario.dynamics.dt, scenario.cost.horizon
    batch, n = decoded.velocity.shape[:2]
    now = observed_time(decoded.time_fraction, scenario.duration, dt).reshape(-1)
    reference_now = decoded.reference_velocity.reshape(-1, 3)
    if isinstance(decoded, DecodedLocalObservation):  # its legs hold the route-return term
        schedule, correction = observed_schedule(decoded, now), None
    else:
        schedule, correction = scenario.schedule, None
        if scenario.avoidance.route_gain > 0:
            # the route-return term is what the reference of a UAV that is not avoiding holds
            # beyond the preset velocity (avoiding UAVs hold their reference anyway)
            correction = reference_now - topology.preset_velocity(schedule, now)
    # Each UAV's own time, reference and avoiding flag: a batch of B·N single-UAV previews.
    preview = topology.reference_preview(
        schedule,
        now,
        dt,
        horizon,
        reference_now[:, None, :],
        decoded.avoiding.reshape(-1, 1),
        correction,
    ).reshape(batch, n, horizon + 1, 3)
    # the obstacles UAV i senses, relative to its own position (the origin of both frames)
    obstacles = {
        "obstacle_centre": decoded.obstacle_relative,
        "obstacle_clearance": namespace_of(decoded.obstacle_radius).where(
            decoded.obstacle_present,
            decoded.obstacle_radius + scenario.cost.obstacle_margin,
            0.0,
        ),
    }
    if isinstance(decoded, DecodedLocalObservation):
        if decoded.neighbour_index is None:
            raise ValueError("local observations need their neighbour_index to exchange plans")
        slots = slot_frame(decoded)
        received = received_slot_plans(plans, decoded.neighbour_index, slots.adjacency)
        cost = prepare_slot_horizon_cost(
            slots.own,
            superposed_rollout(slots.slots, received, dt),
            slots.slot_offsets,
            preview,
            slots.adjacency,
            slots.present,
            scenario.cost,
            dt,
            **obstacles,
        )
    else:
        offsets = asarray_like(scenario.formation.slot_offsets, plans)
        frame = own_frame_views(decoded, offsets)
        trajectories = superposed_rollout(frame.views, received_plans(plans, frame.adjacency), dt)
        cost = prepare_horizon_cost(
            frame.z_own,
            trajectories,
            preview,
            frame.adjacency,
            offsets,
            scenario.cost,
            dt,
            **obstacles,
        )
    half_width = input_half_width(decoded.estimate, scenario.dynamics.u_max)
    return HorizonProblems(cost=cost, half_width=half_width)


def input_half_width(estimate: Any, u_max: float) -> Any:
    """The box ``|u_n,c| <= u_max - |u_d,c|`` of the formation input, ``u_d = -estimate``: the
    part of the actuator range the plant leaves to u_n while the observer compensates
    (docs/model.md §1.5), at least 0.

    Args:
        estimate: (..., 3) disturbance estimate [m/s^2] (numpy or torch).
        u_max: per-axis actuator bound [m/s^2].

    Returns:
        (..., 3) per-axis half width [m/s^2].
    """
    xp = namespace_of(estimate)
    return xp.maximum(u_max - xp.abs(estimate), 0.0)
