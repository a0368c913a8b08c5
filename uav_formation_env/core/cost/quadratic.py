"""Exact quadratic form of J_i in the own inputs, the clearance remainders, and the linear
prediction model they are identified with (numpy or torch arrays; the cached unit responses are
numpy constants, moved to a tensor's device by
:func:`~uav_formation_env.core.array_api.constant_like`)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from uav_formation_env.core.array_api import (
    add_at,
    constant_like,
    device,
    einsum_in,
    namespace_of,
)
from uav_formation_env.core.cost.stage import take_flat
from uav_formation_env.core.dynamics import rollout


@dataclass(frozen=True)
class ClearanceCost:
    """A squared-hinge clearance term of J_i for the pairs that can be active, for population
    evaluation: ``w Σ_pairs Σ_k max(0, d_pair - ||p_i(k) - q_pair(k)||)²``.

    Two terms of J_i have this form: the separation term (3-D positions of the receiver and a
    sender's predicted positions, d = d_s; :meth:`HorizonCost.separation_part`) and the obstacle
    term (horizontal positions against an obstacle's centre, d = its clearance radius, over the
    horizon and its free continuation; :meth:`HorizonCost.obstacle_part`). Problems are the
    flattened (B·R) receivers; a pair is (problem, sender or obstacle).

    Attributes:
        shape: (B, R) of the problem grid.
        rows: (K,) problems with at least one kept pair.
        pair_row: (A,) position in ``rows`` of each kept pair's problem.
        free: (K, T·D) free-response positions of those problems at the T points [m].
        response: (3H, T·D) position rows of the unit input responses [m per m/s^2].
        others: (A, T, D) each pair's other point (a sender's predicted positions, an
            obstacle's centre) [m].
        weight: the term's weight [1/m²].
        distance: (A,) each pair's clearance d [m].
    """

    shape: tuple[int, int]
    rows: np.ndarray
    pair_row: np.ndarray
    free: np.ndarray
    response: np.ndarray
    others: np.ndarray
    weight: float
    distance: np.ndarray

    def total(self, candidates: np.ndarray) -> np.ndarray:
        """The term of candidates (B, R, P, H, 3) [m/s^2] -> (B, R, P)."""
        xp = namespace_of(candidates)
        batch, n_recv, size = candidates.shape[:3]
        where = {"dtype": candidates.dtype, "device": device(candidates)}
        out = xp.zeros((batch * n_recv, size), **where)
        n_rows = self.rows.shape[0]
        if n_rows:
            points, dims = self.others.shape[1:]
            x = candidates.reshape(batch * n_recv, size, -1)[self.rows]  # (K, P, 3H)
            position = (x @ self.response + self.free[:, None]).reshape(-1, size, points, dims)
            diff = position[self.pair_row] - self.others[:, None]  # (A, P, T, D)
            distance = xp.sqrt(einsum_in(xp, "...k,...k->...", diff, diff))
            gap = xp.maximum(self.distance[:, None, None] - distance, 0.0)
            per_pair = einsum_in(xp, "aph,aph->ap", gap, gap)
            summed = xp.zeros((n_rows, size), **where)
            add_at(summed, self.pair_row, per_pair)
            out[self.rows] = self.weight * summed
        return out.reshape(batch, n_recv, size)

    def take(self, index: np.ndarray) -> ClearanceCost:
        """Problems ``index`` (M,) of the flattened (B·R) axis as one copy (grid (1, M)).

        ``index`` holds distinct problems (in any order; an integer array of the library of the
        cost). The kept problems are ordered as in ``index``, each with its pairs in their order.
        """
        xp = namespace_of(self.free)
        index = xp.asarray(index, device=device(self.free))
        n_flat = self.shape[0] * self.shape[1]
        # k of each problem in `rows` (-1: no kept pair), and the position t in `index` of each k
        k_of_flat = xp.full(n_flat, -1, dtype=index.dtype, device=device(index))
        k_of_flat[self.rows] = xp.arange(self.rows.shape[0], device=device(index))
        k_of_t = k_of_flat[index]
        kept_t = xp.nonzero(k_of_t >= 0)[0]  # positions in `index`, in order
        kept_k = k_of_t[kept_t]
        new_of_k = xp.full(self.rows.shape[0], -1, dtype=index.dtype, device=device(index))
        new_of_k[kept_k] = xp.arange(kept_t.shape[0], device=device(index))
        new_row = new_of_k[self.pair_row]  # the new problem of every pair, -1: dropped
        pairs = xp.nonzero(new_row >= 0)[0]
        pairs = pairs[xp.argsort(new_row[pairs], stable=True)]  # grouped by new problem
        return ClearanceCost(
            shape=(1, index.shape[0]),
            rows=kept_t,
            pair_row=new_row[pairs],
            free=self.free[kept_k],
            response=self.response,
            others=self.others[pairs],
            weight=self.weight,
            distance=self.distance[pairs],
        )


@dataclass(frozen=True)
class QuadraticCost:
    """``J(x) = c + g·x + xᵀ Q x + separation(x) + obstacle(x)`` over flattened candidates x
    (n = 3H).

    Built by :meth:`HorizonCost.quadratic`; evaluates a population with one batched matmul (plus
    the clearance terms of the pairs that can be active, if any).

    Attributes:
        constant: (B, R) c = J(0) without the clearance terms.
        linear: (B, R, n) g.
        hessian: (B, R, n, n) Q (symmetric; half the Hessian).
        separation: the separation term, or None if it is off.
        obstacle: the obstacle term, or None if it is off.
    """

    constant: np.ndarray
    linear: np.ndarray
    hessian: np.ndarray
    separation: ClearanceCost | None = None
    obstacle: ClearanceCost | None = None

    @property
    def clearance_terms(self) -> tuple[ClearanceCost, ...]:
        """The terms that are not quadratic in x and hold at least one pair."""
        return tuple(
            term
            for term in (self.separation, self.obstacle)
            if term is not None and term.rows.shape[0]
        )

    def clearance(self, candidates: np.ndarray) -> np.ndarray:
        """The clearance terms of candidates (B, R, P, H, 3) [m/s^2] -> (B, R, P)."""
        total = namespace_of(candidates).zeros(
            candidates.shape[:3], dtype=candidates.dtype, device=device(candidates)
        )
        for term in self.clearance_terms:
            total += term.total(candidates)
        return total

    def total(self, candidates: np.ndarray) -> np.ndarray:
        """J_i of candidates (B, R, P, H, 3) [m/s^2] -> (B, R, P)."""
        batch, n_recv, size = candidates.shape[:3]
        n = self.linear.shape[-1]
        x = candidates.reshape(batch * n_recv, size, n)
        y = x @ self.hessian.reshape(batch * n_recv, n, n)
        y += self.linear.reshape(batch * n_recv, 1, n)
        total = einsum_in(namespace_of(x), "rpk,rpk->rp", y, x)
        total += self.constant.reshape(batch * n_recv, 1)
        total = total.reshape(batch, n_recv, size)
        for term in self.clearance_terms:
            total += term.total(candidates)
        return total

    def take(self, index: np.ndarray) -> QuadraticCost:
        """Receivers ``index`` (M,) of the flattened (B·R) axis as one copy, shapes (1, M, ...)."""
        return QuadraticCost(
            take_flat(self.constant, index),
            take_flat(self.linear, index),
            take_flat(self.hessian, index),
            None if self.separation is None else self.separation.take(index),
            None if self.obstacle is None else self.obstacle.take(index),
        )


@lru_cache(maxsize=8)
def polarisation_points(n: int) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
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
    forced = inputs.reshape(*lead, 3 * horizon) @ constant_like(input_response(horizon, dt), z0)
    forced += z0 @ constant_like(state_response(horizon, dt), z0)
    return forced.reshape(*lead, horizon + 1, 6)
