"""Which UAVs sense each other: every pair, or the pairs within a sensing radius, found through a
uniform horizontal grid so that the work grows linearly in N.

The env's pair terms (the separation term of J_i, the nearest-UAV distance and collisions, the
nearest-others and proximity slots of the local observation) need only UAVs that are close. With
``observation.sensing_radius`` = R set, :func:`sensed_pairs` finds every ordered pair (i, j),
i != j, of one copy with ||p_i - p_j|| <= R without forming the N x N distance matrix: each UAV
falls in a horizontal cell of side R, and only the 3 x 3 cells around its own can hold a UAV
within R. The pair count is then about N times the number of UAVs within R of one, linear in N at
a given density; the cost is a sort of the B·N cell keys and arithmetic on the candidates.

Exactness: the separation term (pairs closer than d_s) and collisions (closer than the collision
distance) are unchanged as long as R is at least both (checked by
:class:`~uav_formation_env.config.Scenario`); the nearest-UAV distance is +inf for a UAV with
nobody within R.

Backends: :func:`pair_distances`, :func:`nearest_distance`, :func:`gap_sq` and
:func:`uav_pairs` take numpy arrays or torch tensors (core/array_api.py). The grid
(:func:`sensed_pairs`, :class:`SensedPairs`, :func:`pair_distance_between`) is numpy-only: its
sort, ``searchsorted`` and segment reductions have no array-API spelling. On torch,
:func:`uav_pairs` therefore always returns the all-pairs matrix, whose consumers apply the radius
themselves (as on numpy below :data:`GRID_MIN_UAVS`): the same nearest distances, separation
terms and collisions as the grid, at O(N²) memory per copy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from uav_formation_env.core.array_api import einsum_in, is_numpy, namespace_of

__all__ = [
    "GRID_MIN_UAVS",
    "SensedPairs",
    "gap_sq",
    "pair_distance_between",
    "pair_distances",
    "nearest_distance",
    "sensed_pairs",
    "uav_pairs",
]

_CELL_BITS = 20  # bits of each cell coordinate in a key; coordinates wrap (mod 2^20 cells)
_CELL_MASK = (1 << _CELL_BITS) - 1
_MAX_COPIES = 1 << (63 - 2 * _CELL_BITS)  # copies per key space (the copy in the top bits)
_AROUND = np.array([(dx, dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1)], dtype=np.int64)


# below this N the (B, N, N) distance matrix is cheaper than the grid's ~30 small array
# operations (benchmarks/bench_scale.py); both give the same pairs within R
GRID_MIN_UAVS = 64


def uav_pairs(positions: np.ndarray, radius: float | None) -> np.ndarray | SensedPairs:
    """The UAV-UAV distances the pair terms need: the (B, N, N) matrix
    (:func:`pair_distances`, +inf on the diagonal) without a
    sensing radius or below :data:`GRID_MIN_UAVS` UAVs (the consumers then ignore the pairs
    beyond R themselves), else the :class:`SensedPairs` within R from the grid.

    ``positions``: (B, N, 3) [m], numpy or torch. The grid is numpy-only: torch positions always
    get the matrix (in their library and device), with the radius left to the consumers as
    below :data:`GRID_MIN_UAVS` (the same nearest distances and separation terms as the grid).
    """
    if (
        radius is None
        or positions.shape[1] < GRID_MIN_UAVS
        or not is_numpy(namespace_of(positions))
    ):
        return pair_distances(positions)
    return sensed_pairs(positions, radius)


def nearest_distance(pairs: np.ndarray | SensedPairs, radius: float | None) -> np.ndarray:
    """(B, N) distance to the nearest other UAV [m]; +inf where none is within ``radius``.

    ``pairs``: the (B, N, N) :func:`pair_distances` (numpy or torch; the result in its library)
    or the (numpy) :class:`SensedPairs`.
    """
    if isinstance(pairs, SensedPairs):
        return pairs.nearest()
    xp = namespace_of(pairs)
    # np.min wraps this ufunc reduction in a Python layer
    nearest = np.minimum.reduce(pairs, axis=-1) if is_numpy(xp) else xp.min(pairs, axis=-1)
    return nearest if radius is None else xp.where(nearest <= radius, nearest, math.inf)


def pair_distances(positions: np.ndarray) -> np.ndarray:
    """Distance between every two UAVs of a copy, with +inf on the diagonal.

    Args:
        positions: (B, N, 3) [m], numpy or torch.

    Returns:
        (B, N, N) ``||p_i - p_j||`` [m] in the library, dtype and device of ``positions``;
        ``[:, i, i]`` is +inf, so that a minimum over j is the nearest other UAV.
    """
    xp = namespace_of(positions)
    batch, n_uav = positions.shape[:2]
    diff = positions[:, :, None, :] - positions[:, None, :, :]
    squared = einsum_in(xp, "...k,...k->...", diff, diff)
    flat = xp.sqrt(squared).reshape(batch, n_uav * n_uav)
    flat[:, :: n_uav + 1] = math.inf
    return flat.reshape(batch, n_uav, n_uav)


def gap_sq(distance: np.ndarray, limit: float) -> np.ndarray:
    """``max(0, limit - distance)²`` elementwise [m²]: one pair's unweighted separation penalty
    (numpy or torch ``distance``)."""
    gap = namespace_of(distance).maximum(limit - distance, 0.0)
    return gap * gap


@dataclass(frozen=True)
class SensedPairs:
    """The ordered UAV pairs (i, j), i != j, of each copy within the sensing radius.

    Attributes:
        batch: B copies.
        n_uav: N UAVs per copy.
        receiver: (P,) int64 flat receiver ``b N + i``, ascending.
        sender: (P,) int64 sender j within its copy, ascending for each receiver.
        distance: (P,) ``||p_i - p_j||`` [m], <= the radius.
        radius: the sensing radius R [m].
    """

    batch: int
    n_uav: int
    receiver: np.ndarray
    sender: np.ndarray
    distance: np.ndarray
    radius: float

    def nearest(self) -> np.ndarray:
        """(B, N) distance to the nearest sensed UAV [m]; +inf where none is within R."""
        out = np.full(self.batch * self.n_uav, np.inf)
        if len(self.receiver):
            starts = np.flatnonzero(np.diff(self.receiver, prepend=-1))
            out[self.receiver[starts]] = np.minimum.reduceat(self.distance, starts)
        return out.reshape(self.batch, self.n_uav)

    def gap_sq_sum(self, limit: float) -> np.ndarray:
        """(B, N) ``Σ_j max(0, limit - d_ij)²`` over the sensed j [m²] (exact for limit <= R)."""
        total = np.bincount(
            self.receiver, weights=gap_sq(self.distance, limit), minlength=self.batch * self.n_uav
        )
        return total.reshape(self.batch, self.n_uav)


def _distance_sq(flat: np.ndarray, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """(P,) ``||flat[first] - flat[second]||²`` of (M, 3) positions [m²]."""
    # one coordinate at a time: gathering (P, 3) rows took 7x longer at P = 6e5
    total = np.zeros(len(first))
    for coordinate in flat.T:
        column = np.ascontiguousarray(coordinate)
        d = column.take(first)
        d -= column.take(second)
        d *= d
        total += d
    return total


def pair_distance_between(flat: np.ndarray, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """(P,) distance [m] between rows ``first`` and ``second`` of (M, 3) positions, computed as
    :func:`sensed_pairs` does."""
    return np.sqrt(_distance_sq(flat, first, second))


def sensed_pairs(positions: np.ndarray, radius: float) -> SensedPairs:
    """Every ordered pair of UAVs of one copy within ``radius`` of each other (module docstring).

    Args:
        positions: (B, N, 3) [m].
        radius: R > 0 [m].

    Returns:
        :class:`SensedPairs`, receivers ascending, senders ascending within a receiver.

    Raises:
        TypeError: ``positions`` is not a numpy array (the grid is numpy-only; on torch,
            :func:`uav_pairs` uses :func:`pair_distances`).
    """
    if not isinstance(positions, np.ndarray):
        raise TypeError(
            "sensed_pairs (the sort-based grid) runs on numpy only, got "
            f"{type(positions).__name__}; on torch use pair_distances (uav_pairs does)"
        )
    batch, n_uav = positions.shape[:2]
    if batch > _MAX_COPIES:  # the copy index would overflow the key: split the batch
        parts = [
            sensed_pairs(positions[start : start + _MAX_COPIES], radius)
            for start in range(0, batch, _MAX_COPIES)
        ]
        shift = np.cumsum([0] + [p.batch * n_uav for p in parts[:-1]])
        return SensedPairs(
            batch,
            n_uav,
            np.concatenate([p.receiver + s for p, s in zip(parts, shift)]),
            np.concatenate([p.sender for p in parts]),
            np.concatenate([p.distance for p in parts]),
            radius,
        )
    flat = np.ascontiguousarray(positions, dtype=float).reshape(-1, 3)
    cell = np.floor(flat[:, :2] / radius).astype(np.int64)  # (M, 2)
    copy = np.repeat(np.arange(batch, dtype=np.int64), n_uav) << (2 * _CELL_BITS)  # (M,)
    key = copy | ((cell[:, 0] & _CELL_MASK) << _CELL_BITS) | (cell[:, 1] & _CELL_MASK)
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    starts = np.flatnonzero(np.diff(sorted_key, prepend=-1))  # first UAV of each occupied cell
    cells = sorted_key[starts]
    counts = np.diff(np.append(starts, len(sorted_key)))
    # the 9 cells around each UAV's own (coordinates wrap like the keys: a far UAV that shares
    # a wrapped cell is only a candidate, dropped by the distance test)
    around = cell[:, None, :] + _AROUND  # (M, 9, 2)
    wanted = (
        copy[:, None]
        | ((around[..., 0] & _CELL_MASK) << _CELL_BITS)
        | (around[..., 1] & _CELL_MASK)
    )
    slot = np.minimum(np.searchsorted(cells, wanted), len(cells) - 1)  # (M, 9)
    count = np.where(cells[slot] == wanted, counts[slot], 0).ravel()
    # candidate (i, j): every UAV of every occupied cell around i
    query = np.repeat(np.arange(count.size), count)
    within = np.arange(query.size) - np.repeat(np.cumsum(count) - count, count)
    receiver = query // len(_AROUND)
    sender = order[starts[slot.ravel()[query]] + within]
    distance_sq = _distance_sq(flat, receiver, sender)
    keep = (receiver != sender) & (distance_sq <= radius * radius)
    receiver, sender = receiver[keep], sender[keep]
    distance = np.sqrt(distance_sq[keep])
    # receivers ascending, then senders (the tie rule of the slot selection is by index)
    ordered = np.argsort(receiver * (batch * n_uav) + sender, kind="stable")
    receiver, sender, distance = receiver[ordered], sender[ordered], distance[ordered]
    return SensedPairs(batch, n_uav, receiver, sender % n_uav, distance, float(radius))
