"""The game cost J_i (eq. 6, SPEC §4): one definition behind the env reward and the MPC objective.

For UAV i over a horizon of H steps, with ``ε_ij(k) = (z_i(k) - z^d_i) - (ẑ_j(k) - z^d_j)``:

    J_i = q Σ_j h_ij Σ_{k<H} ||ε_ij(k)||² + r Σ_{k<H} ||u_i(k)||²
        + m Σ_j h_ij ||ε_ij(H)||² + n Σ_{k<=H} ||v_i(k) - v^d_i(k)||²
        + s Σ_{j≠i} Σ_{k<=H} max(0, d_s - ||p_i(k) - p̂_j(k)||)²

``||x||_w`` is read as ``w xᵀx`` (SPEC §4.1). The last line, the separation term, is not in the
paper (docs/deviations.md §5): it runs over every other UAV j (sensed, not only neighbours) and
vanishes while all UAVs are at least d_s apart. The stage cost, the reward of one realised
transition, is the ``k``-th summand: ``q Σ_j h_ij ||ε_ij||² + r ||u_i||² + n ||v_i - v^d_i||²
+ s Σ_{j≠i} max(0, d_s - ||p_i - p_j||)²``. Both are built from the same term functions below.

Shapes: B scenario copies, N UAVs, P candidates per UAV, H horizon steps.

Neighbour predictions come either as one trajectory per sender, seen alike by every receiver
(B, N, H+1, 6), or as each receiver's own view of every sender (B, N_recv, N_send, H+1, 6): a UAV
that only knows relative states works in its own frame, and the views of a sender differ between
receivers by a translation (and by sensing noise). The formula is the same; only the sum over the
senders runs over the receiver's own views. :func:`prepare_horizon_cost` computes the part of J_i
that does not depend on the candidates once, for optimisers that evaluate many populations.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from uav_formation_env.config import CostConfig
from uav_formation_env.core.dynamics import rollout


@dataclass(frozen=True)
class CostTerms:
    """Named, already weighted terms of J_i, each of the same shape (e.g. (B, N) or (B, N, P))."""

    formation: np.ndarray  # q Σ_j h_ij Σ_k ||ε_ij(k)||²
    energy: np.ndarray  # r Σ_k ||u_i(k)||²
    terminal: np.ndarray  # m Σ_j h_ij ||ε_ij(H)||²
    velocity: np.ndarray  # n Σ_k ||v_i(k) - v^d_i(k)||²
    separation: np.ndarray  # s Σ_{j≠i} Σ_k max(0, d_s - ||p_i(k) - p_j(k)||)²

    @property
    def total(self) -> np.ndarray:
        return self.formation + self.energy + self.terminal + self.velocity + self.separation

    def as_dict(self) -> dict[str, np.ndarray]:
        return {
            "formation": self.formation,
            "energy": self.energy,
            "terminal": self.terminal,
            "velocity": self.velocity,
            "separation": self.separation,
        }


def relative_offset_sign(mirrored: bool) -> float:
    """Sign with which z^d enters the anchored state ``a = z - sign z^d``.

    ``z_ij^d = z^d_i - z^d_j`` (default) gives ``ε_ij = a_i - a_j`` with ``a = z - z^d``; the
    literal reading ``z_ij^d = z^d_j - z^d_i`` (mirrored shape) gives ``a = z + z^d``.
    """
    return -1.0 if mirrored else 1.0


def anchored(z: np.ndarray, offsets: np.ndarray, mirrored: bool = False) -> np.ndarray:
    """States relative to each UAV's formation slot, ``z - z^d`` (or ``z + z^d`` if mirrored).

    Args:
        z: (B, N, *extra, 6) states [m, m/s].
        offsets: (N, 6) formation offsets z^d.
        mirrored: literal mirrored-offset reading.
    """
    extra = z.ndim - 3
    zd = offsets.reshape(offsets.shape[0], *(1,) * extra, 6)
    return z - relative_offset_sign(mirrored) * zd


@dataclass(frozen=True)
class NeighbourMoments:
    """The sender side of ``Σ_j h_ij ||a_i - b_j||²``, summed once for any number of ``a_i``.

    Both sides are moved to a centre per copy (per receiver for per-receiver views) first, so that
    no terms of the size of absolute positions (hundreds of metres) cancel.

    Attributes:
        centre: (B, R, 6) the shift subtracted from both sides.
        degree: (B, R) ``Σ_j h_ij``.
        h_b: (B, R, *tail, 6) ``Σ_j h_ij (b_j - centre)``.
        h_bb: (B, R, *tail) ``Σ_j h_ij ||b_j - centre||²``.
    """

    centre: np.ndarray
    degree: np.ndarray
    h_b: np.ndarray
    h_bb: np.ndarray

    def error_sq(self, own: np.ndarray) -> np.ndarray:
        """``Σ_j h_ij ||own_i - b_j||²``, as ``deg_i ||a_i||² - 2 a_i·h_b + h_bb`` (centred).

        Args:
            own: (B, R, *extra, 6) receivers' anchored states; ``tail`` must be the trailing dims
                of ``extra``.

        Returns:
            (B, R, *extra).
        """
        batch, n_recv = self.degree.shape
        extra, tail = own.ndim - 3, self.h_b.ndim - 3
        a = own - self.centre.reshape(batch, n_recv, *(1,) * extra, 6)
        degree = self.degree.reshape(batch, n_recv, *(1,) * extra)
        lead = (slice(None), slice(None)) + (None,) * (extra - tail)
        return (
            degree * np.einsum("...k,...k->...", a, a)
            - 2.0 * np.einsum("...k,...k->...", a, self.h_b[lead])
            + self.h_bb[lead]
        )

    def take(self, index: np.ndarray) -> NeighbourMoments:
        """The receivers ``index`` of the flattened (B·R) axis, as one copy: shapes (1, M, ...)."""
        return NeighbourMoments(*(_take_flat(x, index) for x in self._fields()))

    def _fields(self) -> tuple[np.ndarray, ...]:
        return self.centre, self.degree, self.h_b, self.h_bb


def _take_flat(x: np.ndarray, index: np.ndarray) -> np.ndarray:
    """Rows ``index`` of ``x`` with its first two axes (B, R) flattened, as (1, M, ...)."""
    return x.reshape(-1, *x.shape[2:])[index][None]


def neighbour_moments(
    others: np.ndarray, adjacency: np.ndarray, per_receiver: bool = False
) -> NeighbourMoments:
    """Sum the senders' side of the formation error (see :class:`NeighbourMoments`).

    Args:
        others: senders' anchored states, either one state per sender seen alike by every
            receiver, (B, N, *tail, 6), or each receiver's own view of every sender,
            (B, R, N, *tail, 6) (``per_receiver=True``; e.g. in each receiver's own frame).
        adjacency: (B, R, N) h_ij, row = receiver.
        per_receiver: whether ``others`` holds per-receiver views.

    Returns:
        :class:`NeighbourMoments` with leading dims (B, R).
    """
    batch, n_recv = adjacency.shape[:2]
    if per_receiver:
        tail = others.ndim - 4
        first = others.reshape(batch, n_recv, others.shape[2], -1, 6)[:, :, :, 0]
        centre = first.mean(axis=2)  # (B, R, 6)
        b = others - centre.reshape(batch, n_recv, 1, *(1,) * tail, 6)
        spec = "bij,bij...->bi..."
    else:
        tail = others.ndim - 3
        first = others.reshape(batch, others.shape[1], -1, 6)[:, :, 0]
        centre = np.broadcast_to(first.mean(axis=1)[:, None], (batch, n_recv, 6))
        b = others - centre[:, :1].reshape(batch, 1, *(1,) * tail, 6)
        spec = "bij,bj...->bi..."
    return NeighbourMoments(
        centre=centre,
        degree=adjacency.sum(axis=-1),
        h_b=np.einsum(spec, adjacency, b),
        h_bb=np.einsum(spec, adjacency, np.einsum("...k,...k->...", b, b)),
    )


def formation_error_sq(
    own: np.ndarray, others: np.ndarray, adjacency: np.ndarray, per_receiver: bool = False
) -> np.ndarray:
    """``Σ_j h_ij ||own_i - others_j||²`` for anchored states, without forming all pairs.

    Expands the square as ``deg_i ||a_i||² - 2 a_i·Σ_j h_ij b_j + Σ_j h_ij ||b_j||²`` after moving
    both sides to the swarm's centre (per copy; per receiver for per-receiver views), so no terms of
    the size of absolute positions (hundreds of metres) cancel.

    Args:
        own: (B, N, *extra, 6) receivers' anchored states, e.g. extra = (P, H+1).
        others: (B, N, *tail, 6) senders' anchored states, where ``tail`` are the trailing dims of
            ``extra`` (e.g. (H+1,)), or ``()``; with ``per_receiver`` each receiver's view of
            every sender, (B, N_recv, N_send, *tail, 6).
        adjacency: (B, N, N) h_ij, row = receiver ((B, N_recv, N_send)).
        per_receiver: whether ``others`` holds per-receiver views.

    Returns:
        (B, N, *extra).
    """
    return neighbour_moments(others, adjacency, per_receiver).error_sq(own)


def velocity_error_sq(velocity: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``||v - v^d||²`` over the last axis; shapes broadcast, (..., 3) -> (...)."""
    diff = velocity - reference
    return np.einsum("...k,...k->...", diff, diff)


def separation_active(weights: CostConfig) -> bool:
    """Whether the separation term can be non-zero (``s > 0`` and ``d_s > 0``)."""
    return weights.separation > 0.0 and weights.separation_distance > 0.0


def others_mask(batch: int, n_uav: int) -> np.ndarray:
    """(B, N, N) 1 for every other UAV j of receiver i, 0 on the diagonal (read-only view)."""
    return np.broadcast_to(1.0 - np.eye(n_uav), (batch, n_uav, n_uav))


def separation_sq(
    own: np.ndarray, others: np.ndarray, mask: np.ndarray, distance: float
) -> np.ndarray:
    """``Σ_j mask_ij max(0, d_s - ||own_i - others_ij||)²``: the unweighted separation penalty.

    Args:
        own: (B, R, *extra, 3) receivers' positions [m], e.g. extra = (P, H+1).
        others: (B, R, S, *tail, 3) each receiver's view of every sender's positions [m], where
            ``tail`` are the trailing dims of ``extra`` (e.g. (H+1,)) or ``()``.
        mask: (B, R, S) which senders count (0 for the receiver itself).
        distance: d_s [m].

    Returns:
        (B, R, *extra) [m²].
    """
    batch, n_recv, n_send = mask.shape
    tail = others.ndim - 4
    lead = own.ndim - 3 - tail
    own = own.reshape(*own.shape[: 2 + lead], 1, *own.shape[2 + lead :])
    others = others.reshape(batch, n_recv, *(1,) * lead, *others.shape[2:])
    diff = own - others  # (B, R, *lead, S, *tail, 3)
    gap = np.maximum(distance - np.sqrt(np.einsum("...k,...k->...", diff, diff)), 0.0)
    weight = mask.reshape(batch, n_recv, *(1,) * lead, n_send, *(1,) * tail)
    return (gap * gap * weight).sum(axis=2 + lead)


def stage_cost(
    z: np.ndarray,
    u_n: np.ndarray,
    reference_velocity: np.ndarray,
    adjacency: np.ndarray,
    offsets: np.ndarray,
    weights: CostConfig,
    mirrored: bool = False,
) -> CostTerms:
    """One summand of J_i on realised states (the env reward is minus its total).

    Args:
        z: (B, N, 6) states [m, m/s].
        u_n: (B, N, 3) formation input (without the compensation u_d) [m/s^2].
        reference_velocity: (B, N, 3) v^d [m/s].
        adjacency: (B, N, N) h_ij.
        offsets: (N, 6) z^d.
        weights: q, r, n, s, d_s (the terminal weight m does not enter a stage).
        mirrored: literal mirrored-offset reading.

    Returns:
        :class:`CostTerms` of shape (B, N) with ``terminal = 0``; ``separation`` runs over every
        other UAV, whatever the adjacency.
    """
    a = anchored(z, offsets, mirrored)
    formation = weights.q * formation_error_sq(a, a, adjacency)
    if separation_active(weights):
        batch, n_uav = z.shape[:2]
        positions = z[..., :3]
        others = np.broadcast_to(positions[:, None], (batch, n_uav, n_uav, 3))
        separation = weights.separation * separation_sq(
            positions, others, others_mask(batch, n_uav), weights.separation_distance
        )
    else:
        separation = np.zeros_like(formation)
    return CostTerms(
        formation=formation,
        energy=weights.r * np.einsum("...k,...k->...", u_n, u_n),
        terminal=np.zeros_like(formation),
        velocity=weights.n * velocity_error_sq(z[..., 3:], reference_velocity),
        separation=separation,
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
    """

    free: np.ndarray
    response: np.ndarray
    own_offset: np.ndarray
    moments: NeighbourMoments
    reference_preview: np.ndarray
    weights: CostConfig
    others_position: np.ndarray
    others_mask: np.ndarray

    def predict(self, candidates: np.ndarray) -> np.ndarray:
        """Predicted states (B, R, P, H+1, 6) of candidates (B, R, P, H, 3), as ``rollout``."""
        *lead, horizon, _ = candidates.shape
        forced = candidates.reshape(*lead, 3 * horizon) @ self.response
        return self.free[:, :, None] + forced.reshape(*lead, horizon + 1, 6)

    def terms(self, candidates: np.ndarray) -> CostTerms:
        """Named terms of J_i for candidates (B, R, P, H, 3) [m/s^2]; each (B, R, P)."""
        return self._terms(candidates, with_separation=True)

    def _terms(self, candidates: np.ndarray, with_separation: bool) -> CostTerms:
        predicted = self.predict(candidates)  # (B, R, P, H+1, 6)
        own = predicted - self.own_offset[:, :, None, None, :]  # anchored, as anchored()
        pair_sq = self.moments.error_sq(own)  # (B, R, P, H+1)
        velocity_sq = velocity_error_sq(predicted[..., 3:], self.reference_preview[:, :, None])
        w = self.weights
        formation = w.q * pair_sq[..., :-1].sum(axis=-1)
        if with_separation and separation_active(w):
            gap_sq = separation_sq(
                predicted[..., :3], self.others_position, self.others_mask, w.separation_distance
            )  # (B, R, P, H+1)
            separation = w.separation * gap_sq.sum(axis=-1)
        else:
            separation = np.zeros_like(formation)
        return CostTerms(
            formation=formation,
            energy=w.r * np.einsum("...hk,...hk->...", candidates, candidates),
            terminal=w.m * pair_sq[..., -1],
            velocity=w.n * velocity_sq.sum(axis=-1),
            separation=separation,
        )

    def terms_total(self, candidates: np.ndarray) -> np.ndarray:
        """J_i of candidates (B, R, P, H, 3) [m/s^2] -> (B, R, P): ``terms(candidates).total``."""
        return self.terms(candidates).total

    def take(self, index: np.ndarray) -> HorizonCost:
        """Receivers ``index`` (M,) of the flattened (B·R) axis as one copy, shapes (1, M, ...)."""
        return HorizonCost(
            free=_take_flat(self.free, index),
            response=self.response,
            own_offset=_take_flat(self.own_offset, index),
            moments=self.moments.take(index),
            reference_preview=_take_flat(self.reference_preview, index),
            weights=self.weights,
            others_position=_take_flat(self.others_position, index),
            others_mask=_take_flat(self.others_mask, index),
        )

    def separation_part(self, half_width: np.ndarray | None = None) -> SeparationCost | None:
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
        batch, n_recv, h1 = self.free.shape[:3]
        horizon = h1 - 1
        response = self.response.reshape(3 * horizon, h1, 6)[:, :, :3].reshape(3 * horizon, -1)
        free = self.free[..., :3]  # (B, R, H+1, 3)
        keep = np.broadcast_to(self.others_mask > 0, self.others_mask.shape)
        if half_width is not None:
            reach = np.tile(np.asarray(half_width, dtype=float), horizon) @ np.abs(response)
            reach = np.sqrt((reach.reshape(batch, n_recv, h1, 3) ** 2).sum(axis=-1))
            diff = free[:, :, None] - self.others_position  # (B, R, S, H+1, 3)
            closest = np.sqrt(np.einsum("...k,...k->...", diff, diff)) - reach[:, :, None]
            keep = keep & (closest.min(axis=-1) < w.separation_distance + 1e-6)
        problem, sender = np.nonzero(keep.reshape(batch * n_recv, -1))
        rows, pair_row = np.unique(problem, return_inverse=True)
        return SeparationCost(
            shape=(batch, n_recv),
            rows=rows,
            pair_row=pair_row.reshape(-1),
            free=free.reshape(batch * n_recv, -1)[rows],
            response=response,
            others=self.others_position.reshape(batch * n_recv, *self.others_position.shape[2:])[
                problem, sender
            ],
            weight=w.separation,
            distance=w.separation_distance,
        )

    def quadratic(self, half_width: np.ndarray | None = None) -> QuadraticCost:
        """J_i as its quadratic part plus the separation term, for fast population evaluation.

        Without the separation term J_i is exactly quadratic in U (affine prediction, squared
        norms), so ``J(x) = c + g·x + xᵀ Q x`` with ``x`` = U flattened to n = 3H components. The
        coefficients of that part are identified from ``1 + 2n + n(n-1)/2`` evaluations of its
        terms (one call) by polarisation, with no second copy of the formula: ``c = J(0)``,
        ``g_i = (J(e_i) - J(-e_i)) / 2``, ``Q_ii = (J(e_i) + J(-e_i)) / 2 - c``,
        ``Q_ij = (J(e_i + e_j) - J(e_i) - J(e_j) + c) / 2``. Their rounding error is about
        1e-16 · |J| per unit input squared. The separation term (not quadratic) is evaluated
        directly, for the pairs :meth:`separation_part` keeps with ``half_width`` (exact for
        candidates in that box; every pair without it).
        """
        batch, n_recv = self.free.shape[:2]
        horizon = self.free.shape[2] - 1
        n = 3 * horizon
        points, upper = _polarisation_points(n)
        values = self._terms(
            np.broadcast_to(
                points.reshape(-1, horizon, 3), (batch, n_recv) + (len(points), horizon, 3)
            ),
            with_separation=False,
        ).total
        c = values[..., 0]
        plus, minus, pairs = (
            values[..., 1 : n + 1],
            values[..., n + 1 : 2 * n + 1],
            values[..., 2 * n + 1 :],
        )
        hessian = np.empty((batch, n_recv, n, n))
        diag = np.arange(n)
        hessian[..., diag, diag] = 0.5 * (plus + minus) - c[..., None]
        i, j = upper
        off = 0.5 * (pairs - plus[..., i] - plus[..., j] + c[..., None])
        hessian[..., i, j] = off
        hessian[..., j, i] = off
        return QuadraticCost(
            constant=c,
            linear=0.5 * (plus - minus),
            hessian=hessian,
            separation=self.separation_part(half_width),
        )


@dataclass(frozen=True)
class SeparationCost:
    """The separation term of J_i for the pairs that can be active, for population evaluation.

    Built by :meth:`HorizonCost.separation_part`. Problems are the flattened (B·R) receivers;
    a pair is (problem, sender).

    Attributes:
        shape: (B, R) of the problem grid.
        rows: (K,) problems with at least one kept pair.
        pair_row: (A,) position in ``rows`` of each kept pair's problem.
        free: (K, (H+1)·3) free-response positions of those problems [m].
        response: (3H, (H+1)·3) position rows of the unit input responses [m per m/s^2].
        others: (A, H+1, 3) predicted positions of each pair's sender [m].
        weight: s [1/m²].
        distance: d_s [m].
    """

    shape: tuple[int, int]
    rows: np.ndarray
    pair_row: np.ndarray
    free: np.ndarray
    response: np.ndarray
    others: np.ndarray
    weight: float
    distance: float

    def total(self, candidates: np.ndarray) -> np.ndarray:
        """``s Σ_pairs Σ_k max(0, d_s - ||p_i(k) - p̂_j(k)||)²`` of candidates (B, R, P, H, 3)."""
        batch, n_recv, size = candidates.shape[:3]
        out = np.zeros((batch * n_recv, size))
        if self.rows.size:
            h1 = self.others.shape[1]
            x = candidates.reshape(batch * n_recv, size, -1)[self.rows]  # (K, P, 3H)
            position = (x @ self.response + self.free[:, None]).reshape(-1, size, h1, 3)
            diff = position[self.pair_row] - self.others[:, None]  # (A, P, H+1, 3)
            gap = np.maximum(self.distance - np.sqrt(np.einsum("...k,...k->...", diff, diff)), 0)
            per_pair = np.einsum("aph,aph->ap", gap, gap)
            summed = np.zeros((self.rows.size, size))
            np.add.at(summed, self.pair_row, per_pair)
            out[self.rows] = self.weight * summed
        return out.reshape(batch, n_recv, size)

    def take(self, index: np.ndarray) -> SeparationCost:
        """Problems ``index`` (M,) of the flattened (B·R) axis as one copy (grid (1, M))."""
        index = np.asarray(index)
        position = {int(row): k for k, row in enumerate(self.rows)}
        new_rows, free, pair_row, others = [], [], [], []
        for t, flat in enumerate(index.tolist()):
            k = position.get(int(flat))
            if k is None:
                continue
            pairs = np.flatnonzero(self.pair_row == k)
            pair_row.extend([len(new_rows)] * pairs.size)
            new_rows.append(t)
            free.append(self.free[k])
            others.append(self.others[pairs])
        h1 = self.others.shape[1]
        return SeparationCost(
            shape=(1, index.size),
            rows=np.asarray(new_rows, dtype=np.int64),
            pair_row=np.asarray(pair_row, dtype=np.int64),
            free=np.asarray(free).reshape(len(new_rows), self.free.shape[1]),
            response=self.response,
            others=np.concatenate(others) if others else np.zeros((0, h1, 3)),
            weight=self.weight,
            distance=self.distance,
        )


@dataclass(frozen=True)
class QuadraticCost:
    """``J(x) = c + g·x + xᵀ Q x + separation(x)`` over flattened candidates x (n = 3H).

    Built by :meth:`HorizonCost.quadratic`; evaluates a population with one batched matmul (plus
    the separation term of the pairs that can be active, if any).

    Attributes:
        constant: (B, R) c = J(0) without the separation term.
        linear: (B, R, n) g.
        hessian: (B, R, n, n) Q (symmetric; half the Hessian).
        separation: the separation term, or None if it is off.
    """

    constant: np.ndarray
    linear: np.ndarray
    hessian: np.ndarray
    separation: SeparationCost | None = None

    def total(self, candidates: np.ndarray) -> np.ndarray:
        """J_i of candidates (B, R, P, H, 3) [m/s^2] -> (B, R, P)."""
        batch, n_recv, size = candidates.shape[:3]
        n = self.linear.shape[-1]
        x = candidates.reshape(batch * n_recv, size, n)
        y = x @ self.hessian.reshape(batch * n_recv, n, n)
        y += self.linear.reshape(batch * n_recv, 1, n)
        total = np.einsum("rpk,rpk->rp", y, x)
        total += self.constant.reshape(batch * n_recv, 1)
        total = total.reshape(batch, n_recv, size)
        if self.separation is not None and self.separation.rows.size:
            total += self.separation.total(candidates)
        return total

    def take(self, index: np.ndarray) -> QuadraticCost:
        """Receivers ``index`` (M,) of the flattened (B·R) axis as one copy, shapes (1, M, ...)."""
        return QuadraticCost(
            _take_flat(self.constant, index),
            _take_flat(self.linear, index),
            _take_flat(self.hessian, index),
            None if self.separation is None else self.separation.take(index),
        )


@lru_cache(maxsize=8)
def _polarisation_points(n: int) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """Points 0, e_i, -e_i, e_i + e_j (i < j) as (1 + 2n + n(n-1)/2, n), and the pairs (i, j)."""
    eye = np.eye(n)
    i, j = np.triu_indices(n, k=1)
    points = np.concatenate((np.zeros((1, n)), eye, -eye, eye[i] + eye[j]))
    for array in (points, i, j):
        array.flags.writeable = False
    return points, (i, j)


@lru_cache(maxsize=8)
def input_response(horizon: int, dt: float) -> np.ndarray:
    """Rollout from rest of every unit input component: (3H, (H+1)·6) [m, m/s per m/s^2].

    Row ``3k + c`` is the predicted trajectory (flattened (H+1, 6)) when only ``u(k)_c = 1``.
    The result is cached and read-only.
    """
    basis = np.eye(3 * horizon).reshape(3 * horizon, horizon, 3)
    response = rollout(np.zeros(6), basis, dt).reshape(3 * horizon, (horizon + 1) * 6)
    response.flags.writeable = False
    return response


@lru_cache(maxsize=8)
def state_response(horizon: int, dt: float) -> np.ndarray:
    """Rollout under zero inputs of every unit initial-state component: (6, (H+1)·6) [-, s].

    Row ``c`` is the predicted trajectory (flattened (H+1, 6)) from ``z0 = e_c``. The result is
    cached and read-only.
    """
    response = rollout(np.eye(6), np.zeros((6, horizon, 3)), dt).reshape(6, (horizon + 1) * 6)
    response.flags.writeable = False
    return response


def superposed_rollout(z0: np.ndarray, inputs: np.ndarray, dt: float) -> np.ndarray:
    """:func:`~uav_formation_env.core.dynamics.rollout` by superposition of its cached unit
    responses (:func:`state_response`, :func:`input_response`): two matmuls instead of the
    cumulative sums; the same trajectories up to floating-point rounding.

    Args:
        z0: (..., 6) initial states [m, m/s].
        inputs: (..., H, 3) input sequences [m/s^2] (same leading dims).
        dt: step length [s].

    Returns:
        (..., H + 1, 6).
    """
    *lead, horizon, _ = inputs.shape
    forced = inputs.reshape(*lead, 3 * horizon) @ input_response(horizon, dt)
    forced += z0 @ state_response(horizon, dt)
    return forced.reshape(*lead, horizon + 1, 6)


def prepare_horizon_cost(
    z0: np.ndarray,
    neighbour_trajectories: np.ndarray,
    reference_preview: np.ndarray,
    adjacency: np.ndarray,
    offsets: np.ndarray,
    weights: CostConfig,
    dt: float,
    mirrored: bool = False,
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
        weights: q, r, m, n, s, d_s.
        dt: control step δ [s].
        mirrored: literal mirrored-offset reading.
    """
    per_receiver = neighbour_trajectories.ndim == 5
    n_uav = offsets.shape[0]
    send_offsets = (
        offsets.reshape(1, 1, n_uav, 1, 6) if per_receiver else offsets.reshape(1, n_uav, 1, 6)
    )
    others = neighbour_trajectories - relative_offset_sign(mirrored) * send_offsets
    horizon = reference_preview.shape[-2] - 1
    batch, n_recv = z0.shape[:2]
    positions = neighbour_trajectories[..., :3]
    if not per_receiver:
        positions = np.broadcast_to(positions[:, None], (batch, n_recv, *positions.shape[1:]))
    free = (z0 @ state_response(horizon, dt)).reshape(*z0.shape[:-1], horizon + 1, 6)
    return HorizonCost(
        free=free,
        response=input_response(horizon, dt),
        own_offset=z0 - anchored(z0, offsets, mirrored),
        moments=neighbour_moments(others, adjacency, per_receiver),
        reference_preview=reference_preview,
        weights=weights,
        others_position=positions,
        others_mask=others_mask(batch, n_recv),
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
    mirrored: bool = False,
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
        weights: q, r, m, n, s, d_s.
        dt: control step δ [s].
        mirrored: literal mirrored-offset reading.

    Returns:
        :class:`CostTerms` of shape (B, N, P).
    """
    return prepare_horizon_cost(
        z0, neighbour_trajectories, reference_preview, adjacency, offsets, weights, dt, mirrored
    ).terms(candidates)
