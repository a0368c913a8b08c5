"""J_i over a horizon of candidate input sequences: the MPC objective, prepared once per step.

Backend-neutral: the arrays of a :class:`HorizonCost` live in the library and on the device of
the measured states it was prepared from (numpy, or torch; :mod:`uav_formation_env.core.array_api`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from uav_formation_env.config import CostConfig
from uav_formation_env.core.array_api import (
    amin,
    as_float,
    asarray_like,
    constant_like,
    device,
    einsum_in,
    namespace_of,
)
from uav_formation_env.core.cost.quadratic import (
    ClearanceCost,
    QuadraticCost,
    input_response,
    polarisation_points,
    state_response,
)
from uav_formation_env.core.cost.stage import (
    CostTerms,
    NeighbourMoments,
    anchored,
    neighbour_moments,
    obstacle_active,
    others_mask,
    separation_active,
    separation_sq,
    take_flat,
    velocity_error_sq,
)


@dataclass(frozen=True)
class HorizonCost:
    """J_i of candidate sequences, with everything that does not depend on them computed once.

    Built by :func:`prepare_horizon_cost`; :func:`horizon_cost` is ``prepare(...).terms(...)``,
    so an optimiser that evaluates many populations against the same neighbour predictions uses
    the same definition without recomputing the senders' side.

    The prediction is affine in the inputs, so it is evaluated by superposition of two
    :func:`~uav_formation_env.core.dynamics.rollout` results computed once: the free response of
    ``z0`` (zero inputs) and the response to each unit input component from a zero state (exact
    by linearity; it avoids the horizon cumsums per population).

    Attributes:
        free: (B, R, H+1, 6) rollout of the measured states z(t) under zero inputs [m, m/s].
        response: (3H, (H+1)·6) rollout from rest of each unit input component, row = component
            of the flattened (H, 3) sequence [m, m/s per m/s^2].
        own_offset: (B, R, 6) what anchoring subtracts from each receiver's states (± z^d_i).
        moments: the neighbours' side of the formation error, leading dims (B, R).
        reference_preview: (B, R, H+1, 3) v^d_i(t + kδ) [m/s].
        weights: q, r, m, n, s, d_s.
        others_position: (B, R, S, H+1, 3) each receiver's prediction of every sender's position
            p̂_j(k) (in the receiver's frame) [m]; only the separation term reads it.
        others_mask: (B, R, S) 1 for the senders the separation term counts (every other UAV).
        obstacle_centre: (B, R, M, 2) the horizontal centres of the M obstacles each receiver
            senses, relative to its position at time t (the frame's origin) [m]; None: none.
        obstacle_clearance: (B, R, M) their clearance radii R + c_o, 0 for an absent slot [m].
        lookahead: (L,) times after the horizon's end at which the obstacle term is also
            evaluated on the free continuation, jδ for j = 1..L [s].
    """

    free: np.ndarray
    response: np.ndarray
    own_offset: np.ndarray
    moments: NeighbourMoments
    reference_preview: np.ndarray
    weights: CostConfig
    others_position: np.ndarray
    others_mask: np.ndarray
    obstacle_centre: np.ndarray | None = None
    obstacle_clearance: np.ndarray | None = None
    lookahead: np.ndarray | None = None

    def predict(self, candidates: np.ndarray) -> np.ndarray:
        """Predicted states (B, R, P, H+1, 6) of candidates (B, R, P, H, 3), as ``rollout``."""
        *lead, horizon, _ = candidates.shape
        forced = candidates.reshape(*lead, 3 * horizon) @ self.response
        return self.free[:, :, None] + forced.reshape(*lead, horizon + 1, 6)

    def terms(self, candidates: np.ndarray) -> CostTerms:
        """Named terms of J_i for candidates (B, R, P, H, 3) [m/s^2]; each (B, R, P)."""
        return self._terms(candidates, with_clearance=True)

    def _terms(self, candidates: np.ndarray, with_clearance: bool) -> CostTerms:
        predicted = self.predict(candidates)  # (B, R, P, H+1, 6)
        own = predicted - self.own_offset[:, :, None, None, :]  # anchored, as anchored()
        pair_sq = self.moments.error_sq(own)  # (B, R, P, H+1)
        velocity_sq = velocity_error_sq(predicted[..., 3:], self.reference_preview[:, :, None])
        xp, w = namespace_of(predicted), self.weights
        formation = w.q * pair_sq[..., :-1].sum(axis=-1)
        if with_clearance and separation_active(w):
            gap_sq = separation_sq(
                predicted[..., :3], self.others_position, self.others_mask, w.separation_distance
            )  # (B, R, P, H+1)
            separation = w.separation * gap_sq.sum(axis=-1)
        else:
            separation = xp.zeros_like(formation)
        if with_clearance and self._has_obstacles:
            points = self._obstacle_points(predicted)  # (B, R, P, T, 2)
            diff = points[..., None, :] - self.obstacle_centre[:, :, None, None]  # (.., T, M, 2)
            distance = xp.sqrt(einsum_in(xp, "...k,...k->...", diff, diff))
            gap = xp.maximum(self.obstacle_clearance[:, :, None, None] - distance, 0.0)
            obstacle = w.obstacle * einsum_in(xp, "...tm,...tm->...", gap, gap)
        else:
            obstacle = xp.zeros_like(formation)
        return CostTerms(
            formation=formation,
            energy=w.r * einsum_in(xp, "...hk,...hk->...", candidates, candidates),
            terminal=w.m * pair_sq[..., -1],
            velocity=w.n * velocity_sq.sum(axis=-1),
            separation=separation,
            obstacle=obstacle,
        )

    @property
    def _has_obstacles(self) -> bool:
        return (
            obstacle_active(self.weights)
            and self.obstacle_centre is not None
            and self.obstacle_centre.shape[2] > 0
        )

    def _obstacle_points(self, states: np.ndarray) -> np.ndarray:
        """(..., H+1, 6) states -> (..., T, 2) the horizontal positions the obstacle term reads:
        k = 0..H, then the free continuation p(H) + jδ v(H), j = 1..L (T = H+1+L). Linear, so it
        maps unit input responses as it maps trajectories."""
        xp = namespace_of(states)
        lookahead = self.lookahead
        if lookahead is None or lookahead.shape[0] == 0:
            return states[..., :2]
        end = states[..., -1:, :]
        ahead = end[..., :2] + lookahead[:, None] * end[..., 3:5]  # (..., L, 2)
        return xp.concat((states[..., :2], ahead), axis=-2)

    def terms_total(self, candidates: np.ndarray) -> np.ndarray:
        """J_i of candidates (B, R, P, H, 3) [m/s^2] -> (B, R, P): ``terms(candidates).total``."""
        return self.terms(candidates).total

    def take(self, index: np.ndarray) -> HorizonCost:
        """Receivers ``index`` (M,) of the flattened (B·R) axis as one copy, shapes (1, M, ...)."""
        return HorizonCost(
            free=take_flat(self.free, index),
            response=self.response,
            own_offset=take_flat(self.own_offset, index),
            moments=self.moments.take(index),
            reference_preview=take_flat(self.reference_preview, index),
            weights=self.weights,
            others_position=take_flat(self.others_position, index),
            others_mask=take_flat(self.others_mask, index),
            obstacle_centre=(
                None if self.obstacle_centre is None else take_flat(self.obstacle_centre, index)
            ),
            obstacle_clearance=(
                None
                if self.obstacle_clearance is None
                else take_flat(self.obstacle_clearance, index)
            ),
            lookahead=self.lookahead,
        )

    def separation_part(self, half_width: np.ndarray | None = None) -> ClearanceCost | None:
        """The separation term on its own, for population evaluation; None if it is off.

        With ``half_width`` (B, R, 3), the per-axis bound ``|u_c(k)| <= half_width_c`` of the
        candidates (the optimiser's box), only the (receiver, sender) pairs that can come closer
        than d_s for SOME candidate in the box are kept: a pair is dropped when, at every k, the
        free-response distance minus the largest displacement the box allows,
        ``||Σ_m |response_m(k)| half_width||`` per axis, is at least d_s (+1 µm). For candidates
        inside the box the result is then exactly the full term (the dropped pairs contribute
        ``max(0, ·) = 0``); outside the box it is not. Without ``half_width`` every pair is kept.
        """
        w = self.weights
        if not separation_active(w):
            return None
        xp = namespace_of(self.free)
        h1 = self.free.shape[2]
        limit = xp.full(
            self.others_mask.shape, w.separation_distance, dtype=self.free.dtype,
            device=device(self.free),
        )  # fmt: skip
        return _screened_clearance(
            self.free[..., :3],
            self.response.reshape(-1, h1, 6)[:, :, :3],
            self.others_position,
            self.others_mask > 0,
            limit,
            w.separation,
            half_width,
        )

    def obstacle_part(self, half_width: np.ndarray | None = None) -> ClearanceCost | None:
        """The obstacle term on its own, for population evaluation; None if it is off or no
        receiver senses an obstacle.

        With ``half_width`` (B, R, 3) only the (receiver, obstacle) pairs that can come within
        the clearance radius for SOME candidate in the box are kept, by the screen of
        :meth:`separation_part` over the term's points (the horizon and its free continuation):
        exact for candidates in the box.
        """
        if not self._has_obstacles:
            return None
        h1 = self.free.shape[2]
        return _screened_clearance(
            self._obstacle_points(self.free),
            self._obstacle_points(self.response.reshape(-1, h1, 6)),
            self.obstacle_centre[:, :, :, None],
            self.obstacle_clearance > 0,
            self.obstacle_clearance,
            self.weights.obstacle,
            half_width,
        )

    def quadratic(self, half_width: np.ndarray | None = None) -> QuadraticCost:
        """J_i as its quadratic part plus the clearance terms, for fast population evaluation.

        Without the clearance terms (separation, obstacle) J_i is exactly quadratic in U (affine
        prediction, squared norms), so ``J(x) = c + g·x + xᵀ Q x`` with ``x`` = U flattened to
        n = 3H components. The
        coefficients of that part are identified from ``1 + 2n + n(n-1)/2`` evaluations of its
        terms (one call) by polarisation, with no second copy of the formula: ``c = J(0)``,
        ``g_i = (J(e_i) - J(-e_i)) / 2``, ``Q_ii = (J(e_i) + J(-e_i)) / 2 - c``,
        ``Q_ij = (J(e_i + e_j) - J(e_i) - J(e_j) + c) / 2``. Their rounding error is about
        1e-16 · |J| per unit input squared. The clearance terms (not quadratic) are evaluated
        directly, for the pairs :meth:`separation_part` and :meth:`obstacle_part` keep with
        ``half_width`` (exact for candidates in that box; every pair without it).
        """
        xp = namespace_of(self.free)
        batch, n_recv = self.free.shape[:2]
        horizon = self.free.shape[2] - 1
        n = 3 * horizon
        points, upper = polarisation_points(n)
        points = constant_like(points, self.free)
        values = self._terms(
            xp.broadcast_to(
                points.reshape(-1, horizon, 3), (batch, n_recv) + (points.shape[0], horizon, 3)
            ),
            with_clearance=False,
        ).total
        c = values[..., 0]
        plus, minus, pairs = (
            values[..., 1 : n + 1],
            values[..., n + 1 : 2 * n + 1],
            values[..., 2 * n + 1 :],
        )
        hessian = xp.empty((batch, n_recv, n, n), dtype=values.dtype, device=device(values))
        diag = xp.arange(n, device=device(values))
        hessian[..., diag, diag] = 0.5 * (plus + minus) - c[..., None]
        i, j = (constant_like(k, values) for k in upper)
        off = 0.5 * (pairs - plus[..., i] - plus[..., j] + c[..., None])
        hessian[..., i, j] = off
        hessian[..., j, i] = off
        return QuadraticCost(
            constant=c,
            linear=0.5 * (plus - minus),
            hessian=hessian,
            separation=self.separation_part(half_width),
            obstacle=self.obstacle_part(half_width),
        )


def _screened_clearance(
    free: np.ndarray,
    response: np.ndarray,
    others: np.ndarray,
    keep: np.ndarray,
    limit: np.ndarray,
    weight: float,
    half_width: np.ndarray | None,
) -> ClearanceCost:
    """A clearance term's (receiver, other) pairs as a :class:`ClearanceCost`, screened by the
    box (:meth:`HorizonCost.separation_part`).

    Args:
        free: (B, R, T, D) the receivers' free-response points [m].
        response: (3H, T, D) the points' unit input responses [m per m/s^2].
        others: (B, R, S, T, D), or (B, R, S, 1, D) for fixed points, each pair's other point.
        keep: (B, R, S) bool, the pairs that count.
        limit: (B, R, S) each pair's clearance [m].
        weight: the term's weight.
        half_width: (B, R, 3) the box ``|u_c(k)| <= half_width_c``, or None (keep every pair).
    """
    xp = namespace_of(free)
    batch, n_recv, n_points, dims = free.shape
    horizon = response.shape[0] // 3
    response = response.reshape(3 * horizon, n_points * dims)
    if half_width is not None:
        reach = xp.tile(as_float(half_width, free), (horizon,)) @ xp.abs(response)
        reach = xp.sqrt(xp.sum(reach.reshape(batch, n_recv, n_points, dims) ** 2, axis=-1))
        diff = free[:, :, None] - others  # (B, R, S, T, D)
        distance = xp.sqrt(einsum_in(xp, "...k,...k->...", diff, diff))
        closest = amin(distance - reach[:, :, None], axis=-1)  # (B, R, S)
        keep = keep & (closest < limit + 1e-6)
    keep = xp.broadcast_to(keep, limit.shape)
    problem, other = xp.nonzero(keep.reshape(batch * n_recv, -1))
    rows, pair_row = xp.unique_inverse(problem)
    n_other = limit.shape[2]
    paired = xp.broadcast_to(others, (batch, n_recv, n_other, n_points, dims))
    return ClearanceCost(
        shape=(batch, n_recv),
        rows=rows,
        pair_row=pair_row.reshape(-1),
        free=free.reshape(batch * n_recv, -1)[rows],
        response=response,
        others=paired.reshape(batch * n_recv, n_other, n_points, dims)[problem, other],
        weight=weight,
        distance=limit.reshape(batch * n_recv, -1)[problem, other],
    )


@lru_cache(maxsize=16)
def lookahead_times(steps: int, dt: float) -> np.ndarray:
    """(L,) times jδ, j = 1..L, after the horizon's end at which the obstacle term reads the free
    continuation [s] (cached and read-only, so that :func:`constant_like` may cache it too)."""
    times = dt * np.arange(1, steps + 1, dtype=float)
    times.flags.writeable = False
    return times


def prepare_horizon_cost(
    z0: np.ndarray,
    neighbour_trajectories: np.ndarray,
    reference_preview: np.ndarray,
    adjacency: np.ndarray,
    offsets: np.ndarray,
    weights: CostConfig,
    dt: float,
    obstacle_centre: np.ndarray | None = None,
    obstacle_clearance: np.ndarray | None = None,
) -> HorizonCost:
    """The candidate-independent part of :func:`horizon_cost` (same arguments, no candidates).

    Args:
        z0: (B, N, 6) measured states at time t [m, m/s].
        neighbour_trajectories: (B, N, H+1, 6) each UAV's broadcast prediction ẑ_j(k), k = 0..H,
            seen alike by every receiver; or (B, N, N, H+1, 6) each receiver i's own view of
            every sender j (``[:, i, j]``), e.g. in i's own frame. The formation terms read the
            rows with h_ij = 1; the separation term reads the positions of every j ≠ i.
        reference_preview: (B, N, H+1, 3) v^d_i(t + kδ) [m/s].
        adjacency: (B, N, N) h_ij, row = receiver.
        offsets: (N, 6) z^d.
        weights: q, r, m, n, s, d_s and the obstacle term's o, c_o, L.
        dt: control step δ [s].
        obstacle_centre: (B, R, M, 2) horizontal centres of the obstacles each receiver senses,
            in the coordinates of ``z0`` [m]; None: no obstacle term.
        obstacle_clearance: (B, R, M) their clearance radii R + c_o, 0 for an absent one [m].
    """
    xp = namespace_of(z0)
    offsets = asarray_like(offsets, z0)  # e.g. the config's, as numpy
    if not isinstance(z0, np.ndarray):
        adjacency = asarray_like(adjacency, z0)
    per_receiver = neighbour_trajectories.ndim == 5
    n_uav = offsets.shape[0]
    send_offsets = (
        offsets.reshape(1, 1, n_uav, 1, 6) if per_receiver else offsets.reshape(1, n_uav, 1, 6)
    )
    others = neighbour_trajectories - send_offsets
    batch, n_recv = z0.shape[:2]
    positions = neighbour_trajectories[..., :3]
    if not per_receiver:
        positions = xp.broadcast_to(positions[:, None], (batch, n_recv, *positions.shape[1:]))
    return _prepared(
        z0,
        z0 - anchored(z0, offsets),
        neighbour_moments(others, adjacency, per_receiver),
        positions,
        others_mask(batch, n_recv, like=z0),
        reference_preview,
        weights,
        dt,
        obstacle_centre,
        obstacle_clearance,
    )


def prepare_slot_horizon_cost(
    z0: np.ndarray,
    slot_trajectories: np.ndarray,
    slot_offsets: np.ndarray,
    reference_preview: np.ndarray,
    adjacency: np.ndarray,
    present: np.ndarray,
    weights: CostConfig,
    dt: float,
    obstacle_centre: np.ndarray | None = None,
    obstacle_clearance: np.ndarray | None = None,
) -> HorizonCost:
    """:func:`prepare_horizon_cost` for receivers that see S slots (e.g. their k nearest UAVs)
    in their own frame, where the receiver's own formation offset is 0.

    J_i depends on anchored states only through differences ``a_j - a_i`` and on positions only
    through ``p_j - p_i``, so a frame that gives the receiver offset 0 and each slot the offset
    ``z_j - a_j - (z_i - a_i)`` gives the same J_i as global coordinates.

    Args:
        z0: (B, R, 6) the receivers' own states in their frames [m, m/s].
        slot_trajectories: (B, R, S, H+1, 6) each slot's predicted states in the receiver's
            frame [m, m/s].
        slot_offsets: (B, R, S, 6) what anchoring subtracts from each slot's states, relative to
            the receiver's [m, m/s].
        reference_preview: (B, R, H+1, 3) v^d_i(t + kδ) [m/s].
        adjacency: (B, R, S) h_ij of the UAV in each slot (0 for absent slots).
        present: (B, R, S) 1 where the slot holds a UAV (the separation term counts it).
        weights: q, r, m, n, s, d_s and the obstacle term's o, c_o, L.
        dt: control step δ [s].
        obstacle_centre: (B, R, M, 2) horizontal centres of the obstacles each receiver senses,
            in the coordinates of ``z0`` [m]; None: no obstacle term.
        obstacle_clearance: (B, R, M) their clearance radii R + c_o, 0 for an absent one [m].
    """
    return _prepared(
        z0,
        namespace_of(z0).zeros_like(z0),
        neighbour_moments(slot_trajectories - slot_offsets[..., None, :], adjacency, True),
        slot_trajectories[..., :3],
        as_float(present, z0),
        reference_preview,
        weights,
        dt,
        obstacle_centre,
        obstacle_clearance,
    )


def _prepared(
    z0: np.ndarray,
    own_offset: np.ndarray,
    moments: NeighbourMoments,
    others_position: np.ndarray,
    mask: np.ndarray,
    reference_preview: np.ndarray,
    weights: CostConfig,
    dt: float,
    obstacle_centre: np.ndarray | None,
    obstacle_clearance: np.ndarray | None,
) -> HorizonCost:
    """The :class:`HorizonCost` of prepared senders' terms: the receivers' free response and the
    unit input responses are computed here, once for both frames."""
    horizon = reference_preview.shape[-2] - 1
    free = (z0 @ constant_like(state_response(horizon, dt), z0)).reshape(
        *z0.shape[:-1], horizon + 1, 6
    )
    if obstacle_centre is not None:
        if obstacle_clearance is None:
            raise ValueError("obstacle_centre needs obstacle_clearance, the radii R + c_o")
        obstacle_centre = asarray_like(obstacle_centre, z0)
        obstacle_clearance = asarray_like(obstacle_clearance, z0)
    return HorizonCost(
        free=free,
        response=constant_like(input_response(horizon, dt), z0),
        own_offset=own_offset,
        moments=moments,
        reference_preview=reference_preview,
        weights=weights,
        others_position=others_position,
        others_mask=mask,
        obstacle_centre=obstacle_centre,
        obstacle_clearance=obstacle_clearance,
        lookahead=constant_like(lookahead_times(weights.obstacle_lookahead, dt), z0),
    )


def horizon_cost(
    candidates: np.ndarray,
    z0: np.ndarray,
    neighbour_trajectories: np.ndarray,
    reference_preview: np.ndarray,
    adjacency: np.ndarray,
    offsets: np.ndarray,
    weights: CostConfig,
    dt: float,
    obstacle_centre: np.ndarray | None = None,
    obstacle_clearance: np.ndarray | None = None,
) -> CostTerms:
    """J_i of every candidate input sequence of every UAV against its neighbours' predictions.

    Args:
        candidates: (B, N, P, H, 3) candidate u_n sequences of each UAV [m/s^2].
        z0: (B, N, 6) measured states at time t [m, m/s].
        neighbour_trajectories: (B, N, H+1, 6) each UAV's broadcast prediction ẑ_j(k), k = 0..H;
            or per-receiver views (B, N, N, H+1, 6), see :func:`prepare_horizon_cost`.
        reference_preview: (B, N, H+1, 3) v^d_i(t + kδ) [m/s].
        adjacency: (B, N, N) h_ij, row = receiver.
        offsets: (N, 6) z^d.
        weights: q, r, m, n, s, d_s and the obstacle term's o, c_o, L.
        dt: control step δ [s].
        obstacle_centre: (B, N, M, 2) horizontal centres of the obstacles each UAV senses, in
            the coordinates of ``z0`` [m]; None: no obstacle term.
        obstacle_clearance: (B, N, M) their clearance radii R + c_o, 0 for an absent one [m].

    Returns:
        :class:`CostTerms` of shape (B, N, P).
    """
    return prepare_horizon_cost(
        z0,
        neighbour_trajectories,
        reference_preview,
        adjacency,
        offsets,
        weights,
        dt,
        obstacle_centre,
        obstacle_clearance,
    ).terms(candidates)
