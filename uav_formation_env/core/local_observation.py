"""Local observations of fixed length: what UAV i senses or receives, whatever the swarm size N.

:mod:`uav_formation_env.core.observation` gives every other UAV a slot, so its length grows with N
and a policy trained at one N cannot act at another. Here UAV i sees its own state, its ``k``
nearest in-neighbours (then the nearest other UAVs), ``r`` proximity slots and its ``m`` nearest
obstacles, so the length is ``dim = 19 + 11 (k + r) + 5 m`` (95 for the defaults k = 4, r = 2,
m = 2) for any N. The slot table (every slot's meaning, unit and scale) and the reasons for the
defaults are in docs/scenarios.md, "The observation independent of N";
:func:`decode_local_observations` is its inverse.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from uav_formation_env.config import Scenario
from uav_formation_env.core.array_api import (
    as_float,
    asarray_like,
    clip_in_place,
    constant_like,
    device,
    einsum_in,
    is_numpy,
    namespace_of,
    read_only,
    subtract_into,
)
from uav_formation_env.core.cost import anchored
from uav_formation_env.core.cost.stage import pair_distances
from uav_formation_env.core.observation import (
    DISTANCE_CLIP,
    DISTANCE_SCALE,
    ESTIMATE_SCALE,
    FORMATION_SCALE,
    OBSERVATION_BOUND,
    VELOCITY_SCALE,
    _as_tensor_like,
    observation_dim,
)
from uav_formation_env.core.proximity import SensedPairs, pair_distance_between

TIME_SCALE = 50.0  # [s]
TIME_CLIP = 10.0  # clip of the scaled time to the switch (500 s) [-]
OWN_DIM = 19
NEIGHBOUR_DIM = 11
OBSTACLE_DIM = 5
# int64 sort keys (see _neighbour_keys): in-neighbours have the sign bit set (negative keys),
# absent candidates the largest key; Python ints, so that they combine with numpy and torch keys
_NEIGHBOUR = -(1 << 63)
_SELF = (1 << 63) - 1

Array = Any  # a numpy array or a torch tensor (core/array_api.py)


def _check_slots(k: int, m: int, nearest: int = 0) -> None:
    for name, value in (("k", k), ("m", m), ("nearest", nearest)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
            raise ValueError(f"{name} must be an integer >= 0, got {value!r}")


def local_observation_dim(k: int, m: int, nearest: int = 2) -> int:
    """Length of one agent's local observation with k neighbour slots, ``nearest`` proximity
    slots and m obstacle slots."""
    _check_slots(k, m, nearest)
    return OWN_DIM + NEIGHBOUR_DIM * (k + nearest) + OBSTACLE_DIM * m


@lru_cache(maxsize=16)
def _layout(k: int, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(scale, low, high)``, each (dim,) for k UAV slots (neighbour and proximity slots alike)
    and m obstacle slots: every slot's divisor and clip bounds (read-only)."""
    dim = local_observation_dim(k, m, 0)
    scale = np.ones(dim)
    high = np.full(dim, OBSERVATION_BOUND)
    low = -high
    scale[0:9] = VELOCITY_SCALE
    scale[9:12] = ESTIMATE_SCALE
    scale[14] = DISTANCE_SCALE
    scale[15:18] = VELOCITY_SCALE
    scale[18] = TIME_SCALE
    low[13], high[13] = 0.0, 1.0
    low[14], high[14] = -DISTANCE_CLIP, DISTANCE_CLIP
    low[18], high[18] = 0.0, TIME_CLIP
    # row s of these views is neighbour slot s (then obstacle slot s): fill all slots at once
    end = OWN_DIM + NEIGHBOUR_DIM * k
    sn, ln, hn = (x[OWN_DIM:end].reshape(k, NEIGHBOUR_DIM) for x in (scale, low, high))
    so, lo, ho = (x[end:].reshape(m, OBSTACLE_DIM) for x in (scale, low, high))
    ln[:, 0:2], hn[:, 0:2] = 0.0, 1.0  # present, h_ij
    sn[:, 2:5], ln[:, 2:5], hn[:, 2:5] = DISTANCE_SCALE, -DISTANCE_CLIP, DISTANCE_CLIP
    sn[:, 5:8] = FORMATION_SCALE
    sn[:, 8:11] = VELOCITY_SCALE
    lo[:, 0], ho[:, 0] = 0.0, 1.0  # present
    so[:, 1:5] = DISTANCE_SCALE
    lo[:, [1, 2, 4]], ho[:, [1, 2, 4]] = -DISTANCE_CLIP, DISTANCE_CLIP  # centre, surface
    lo[:, 3] = 0.0  # radius
    read_only(scale, low, high)
    return scale, low, high


def local_observation_bounds(
    k: int = 4, m: int = 2, nearest: int = 2
) -> tuple[np.ndarray, np.ndarray]:
    """``(low, high)``, each (dim,) float32: the clip bounds of every slot, e.g. for a
    ``gymnasium.spaces.Box(low, high, dtype=np.float32)``."""
    _check_slots(k, m, nearest)
    _, low, high = _layout(k + nearest, m)
    return low.astype(np.float32), high.astype(np.float32)


def _take_rows(x: Array, index: Array) -> Array:
    """``take_along_axis(x, index, axis=-1)`` for (..., n) x and (..., j) index, as one flat
    ``take`` (numpy's take_along_axis builds an index grid per call: ~40% of a small build);
    numpy or torch (``x.take`` is the flat take on both)."""
    n = x.shape[-1]
    if isinstance(x, np.ndarray):  # no device lookup (18 calls a build)
        rows = np.arange(0, x.size, n)
    else:
        rows = namespace_of(x).arange(0, math.prod(x.shape), n, device=device(x))
    return x.reshape((-1,)).take(index + rows.reshape((*index.shape[:-1], 1)))


def _k_smallest(key: Array, k: int) -> Array:
    """Indices of the k smallest keys along the last axis, ordered by (key, index).

    numpy or torch: torch takes a stable sort (its ``topk`` breaks ties in no documented order);
    numpy a partial sort with the same result.

    Args:
        key: (..., n) sort keys without NaN.
        k: how many, >= 0.

    Returns:
        (..., min(k, n)) int64; ties are broken by the lowest index, so results are deterministic.
    """
    xp = namespace_of(key)
    n = key.shape[-1]
    if k == 0:
        return xp.zeros((*key.shape[:-1], 0), dtype=xp.int64, device=device(key))
    if k >= n or not is_numpy(xp):
        # a stable sort orders equal keys by index: the (key, index) order
        return xp.argsort(key, axis=-1, stable=True)[..., :k]
    # A partial sort (O(n); a full sort costs ~4x at n = 100) puts the k smallest keys first, in
    # any order. That set is exact unless the k-th and (k+1)-th smallest keys are equal: then
    # argpartition may take any of the tied keys, and those rows are redone by _k_smallest_tied.
    part = np.argpartition(key, k, axis=-1)  # the (k+1)-th smallest at k, smaller ones before
    cols = part[..., :k]
    values = _take_rows(key, cols)
    tied = values.max(axis=-1) == _take_rows(key, part[..., k : k + 1])[..., 0]
    if tied.any():
        cols[tied] = _k_smallest_tied(key[tied], k)
        values = _take_rows(key, cols)
    # order the k by key, then index (lexsort: the last key is the primary one)
    order = np.lexsort((cols, values), axis=-1)
    return _take_rows(cols, order)


def _k_smallest_tied(key: np.ndarray, k: int) -> np.ndarray:
    """(R, k) the k smallest of (R, n) keys by (key, index), in ascending index, for 0 < k < n
    (numpy only: the partial-sort path of :func:`_k_smallest`)."""
    # every key below the k-th smallest t, then the lowest-index keys equal to t: exactly k a row
    t = np.partition(key, k - 1, axis=-1)[:, k - 1 : k]
    below = key < t
    tie = key == t
    need = k - np.count_nonzero(below, axis=-1, keepdims=True)
    chosen = below | (tie & (np.cumsum(tie, axis=-1) <= need))
    return np.nonzero(chosen)[1].reshape(len(key), k)


def _neighbour_keys(distance: Array, neighbour: Array, absent: Array | None) -> Array:
    """(B, N, C) int64 sort keys of each receiver's candidates: in-neighbours by distance, then
    other UAVs, absent candidates (the UAV itself, padding) last (numpy or torch).

    The bits of a non-negative float64 order like its value, so ``bits(d_ij)`` (in [0, 2^63): no
    sign bit) is a key for the non-neighbours and the same bits with the sign bit set (``bits -
    2^63``, negative) one for the in-neighbours: ``d + large (1 - h_ij)`` without rounding, so
    distances never merge, whatever their size. NaN distances count as +inf, -0 as +0. (Signed
    keys since torch sorts no uint64; they order as the unsigned keys with the top bit flipped.)

    Args:
        distance: (B, N, C) candidate distances [m].
        neighbour: (B, N, C) bool, h_ij != 0 (all True: distance alone).
        absent: (B, N, C) bool, candidates that are no UAV to pick; None: the diagonal of an
            all-pairs (C = N) candidate set.
    """
    xp = namespace_of(distance)
    if distance.dtype != xp.float64:  # the bits below are float64's (widening keeps the order)
        distance = xp.astype(distance, xp.float64)
    d = xp.where(distance >= 0.0, distance, xp.inf)
    d += 0.0  # -0 -> +0 (bits 0); in place: a new (B, N, N) array costs page faults at N = 100
    bits = d.view(xp.int64)  # a bit view; the method is numpy's and torch's alike
    key = xp.where(neighbour, bits | _NEIGHBOUR, bits)
    if absent is None:
        batch, n_uav = distance.shape[:2]
        key.reshape((batch, n_uav * n_uav))[:, :: n_uav + 1] = _SELF  # above every other key
    else:
        key[absent] = _SELF
    return key


@dataclass(frozen=True)
class _Candidates:
    """The UAVs each receiver may put in a slot, sorted by UAV index (the tie rule).

    Attributes:
        uav: (B, N, C) int64 UAV j of each candidate column.
        distance: (B, N, C) ||p_i - p_j|| [m].
        neighbour: (B, N, C) bool, h_ij != 0.
        absent: (B, N, C) bool, padding columns; None: all pairs (C = N, the receiver itself on
            the diagonal).
    """

    uav: Array
    distance: Array
    neighbour: Array
    absent: Array | None


def _candidates(
    distance: Array | SensedPairs,
    adjacency: Array,
    positions: Array,
    radius: float | None = None,
) -> _Candidates:
    """The UAVs a slot can hold: the in-neighbours and the UAVs within the sensing radius (all
    other UAVs without one), from a distance matrix (O(N) per receiver; numpy or torch) or from
    the sensed pairs (O(1) per receiver; numpy only, as the grid of core/proximity.py).

    Raises:
        TypeError: sensed pairs with torch positions.
    """
    batch, n_uav = adjacency.shape[:2]
    xp = namespace_of(positions)
    if not isinstance(distance, SensedPairs):
        uav = xp.broadcast_to(xp.arange(n_uav, device=device(positions)), (batch, n_uav, n_uav))
        neighbour = adjacency != 0
        if radius is None:
            return _Candidates(uav, distance, neighbour, None)
        # the same candidates as the grid's: unheard UAVs beyond R (and the diagonal) are absent
        return _Candidates(uav, distance, neighbour, ~neighbour & ~(distance <= radius))
    if not is_numpy(xp):
        raise TypeError(
            "build_local_observations: the sensed pairs (core/proximity.SensedPairs, the numpy "
            "grid) take numpy positions; with torch arrays pass distance as the (B, N, N) "
            "pair-distance tensor (pair_distances) and sensing_radius"
        )
    # in-neighbours (communication) and sensed UAVs (within R), each pair once, sorted by
    # receiver then sender
    b, i, j = np.nonzero(adjacency)
    codes = np.concatenate(
        (distance.receiver * n_uav + distance.sender, (b * n_uav + i) * n_uav + j)
    )
    # two sorted runs: a stable (radix / merge) sort and a dedupe beat np.unique 10x
    codes.sort(kind="stable")
    codes = codes[np.diff(codes, prepend=-1) != 0]
    receiver, sender = codes // n_uav, codes % n_uav
    flat = positions.reshape(-1, 3)
    pair_distance = pair_distance_between(flat, receiver, receiver - receiver % n_uav + sender)
    counts = np.bincount(receiver, minlength=batch * n_uav)
    width = max(int(counts.max(initial=0)), 1)
    column = np.arange(len(receiver)) - (np.cumsum(counts) - counts)[receiver]
    uav = np.full((batch * n_uav, width), -1, dtype=np.int64)
    uav[receiver, column] = sender
    dist = np.full((batch * n_uav, width), np.inf)
    dist[receiver, column] = pair_distance
    neighbour = np.zeros((batch * n_uav, width), dtype=bool)
    neighbour[receiver, column] = np.ravel(adjacency)[codes] != 0
    shape = (batch, n_uav, width)
    return _Candidates(
        uav.reshape(shape), dist.reshape(shape), neighbour.reshape(shape), uav.reshape(shape) < 0
    )


def _select_slots(candidates: _Candidates, k: int, nearest: int) -> Array:
    """(B, N, k + nearest) UAV in each slot, -1 where absent: the k smallest neighbour keys (in-
    neighbours by distance, then the nearest others), then the ``nearest`` closest candidates
    not already taken (proximity slots). numpy or torch, the same slots."""
    uav, absent = candidates.uav, candidates.absent
    xp = namespace_of(uav)
    on = device(uav)
    batch, n_uav, width = uav.shape
    index = xp.full((batch, n_uav, k + nearest), -1, dtype=xp.int64, device=on)
    key = _neighbour_keys(candidates.distance, candidates.neighbour, absent)
    column = _k_smallest(key, k)  # (B, N, min(k, C)); absent columns only after every UAV
    taken = _take_rows(uav, column)
    index[..., : column.shape[-1]] = xp.where(_take_rows(key, column) == _SELF, -1, taken)
    if nearest:
        # the nearest candidates not in a neighbour slot, by distance alone: the ones a
        # collision can come from, whatever the graph (absent and taken ones sort last)
        everyone = xp.ones(uav.shape, dtype=xp.bool, device=on)
        near_key = _neighbour_keys(candidates.distance, everyone, absent)
        rows = xp.arange(batch * n_uav, device=on).reshape((batch, n_uav, 1)) * width
        near_key.reshape((-1,))[(rows + column).reshape((-1,))] = _SELF  # a view: contiguous
        extra = _k_smallest(near_key, nearest)  # (B, N, min(r, C))
        found = xp.where(_take_rows(near_key, extra) == _SELF, -1, _take_rows(uav, extra))
        index[..., k : k + extra.shape[-1]] = found
    return index


@dataclass(frozen=True)
class LocalObservations:
    """Output of :func:`build_local_observations`.

    Attributes:
        obs: (B, N, dim) float32, the learner's vectors (layout in the module docstring).
        neighbour_index: (B, N, k) int64, the UAV j in each neighbour slot, -1 where absent:
            communication metadata (e.g. whose plans to exchange), not part of ``obs``.
    """

    obs: Array
    neighbour_index: Array


def build_local_observations(
    z: Array,
    reference_velocity: Array,
    estimate: Array,
    adjacency: Array,
    avoiding: Array,
    time_fraction: Array,
    offsets: Array,
    obstacle_centers: Array,
    obstacle_radii: Array,
    obstacle_present: Array,
    min_separation: Array,
    k: int = 4,
    m: int = 2,
    next_velocity: Array | None = None,
    time_to_switch: Array | None = None,
    nearest: int = 2,
    distance: Array | SensedPairs | None = None,
    sensing_radius: float | None = None,
) -> LocalObservations:
    """Every agent's local observation (length independent of N), on the array library of ``z``
    (numpy, or torch on any device).

    With torch ``z``, the mission data (``offsets``, the obstacle arrays, ``time_fraction``,
    ``next_velocity``, ``time_to_switch``) may be numpy arrays: they are moved to ``z``'s device;
    ``distance`` must then be the (B, N, N) tensor or None (the sensed pairs are numpy only).
    Values are computed in ``z``'s dtype (float64 from the sim).

    Args:
        z: (B, N, 6) states [m, m/s].
        reference_velocity: (B, N, 3) v^d [m/s].
        estimate: (B, N, 3) disturbance estimate [m/s^2].
        adjacency: (B, N, N) h_ij, row = receiver i (1: i receives from j).
        avoiding: (B, N) bool.
        time_fraction: (B,) t / duration.
        offsets: (N, 6) or (B, N, 6) formation offsets z^d [m, m/s].
        obstacle_centers: (B, O, 2) [m]; any values where the obstacle is absent.
        obstacle_radii: (B, O) [m].
        obstacle_present: (B, O) bool; absent obstacles are padding and never fill a slot.
        min_separation: (B, N) distance to the nearest other UAV [m].
        k: neighbour slots, >= 0.
        m: obstacle slots, >= 0.
        next_velocity: (B, 3) preset velocity of the route's next leg [m/s]; None: each UAV's
            current reference (no change ahead).
        time_to_switch: (B,) time until the next leg starts [s]; None: 0.
        nearest: proximity slots after the k neighbour slots, >= 0: the nearest UAVs not in a
            neighbour slot.
        distance: (B, N, N) :func:`~uav_formation_env.core.cost.stage.pair_distances` of ``z``,
            if the caller has them, or the :class:`~uav_formation_env.core.proximity.
            SensedPairs` within a sensing radius (then the slots hold in-neighbours and sensed
            UAVs only); None: all pairs, computed here.
        sensing_radius: R of a ``distance`` matrix: only in-neighbours and UAVs within R fill
            slots, as with the sensed pairs; None: every UAV.

    Returns:
        :class:`LocalObservations` with obs (B, N, dim) float32 and neighbour_index (B, N, k +
        nearest) int64, of ``z``'s library and device.

    Raises:
        TypeError: sensed pairs with torch ``z``.
    """
    _check_slots(k, m, nearest)
    # Methods that numpy and torch share (x.reshape(shape), the flat x.take(index)) rather than
    # the standard's functions: numpy's function forms add a dispatch layer each.
    xp = namespace_of(z)
    numpy = is_numpy(xp)
    on = device(z)
    batch, n_uav = z.shape[:2]
    slots_count = k + nearest
    scale, low, high = _layout(slots_count, m)
    if numpy:
        offsets = np.asarray(offsets, dtype=float)
        time_fraction = np.asarray(time_fraction)
        time_to_switch = None if time_to_switch is None else np.asarray(time_to_switch)
    else:  # the cached layout and the mission data (maybe numpy) on z's device
        scale, low, high = (constant_like(a, z) for a in (scale, low, high))
        offsets, obstacle_centers, obstacle_radii, time_fraction = (
            asarray_like(a, z) for a in (offsets, obstacle_centers, obstacle_radii, time_fraction)
        )
        next_velocity, time_to_switch = (
            None if a is None else asarray_like(a, z) for a in (next_velocity, time_to_switch)
        )
        obstacle_present = _as_tensor_like(obstacle_present, z)
    end = OWN_DIM + NEIGHBOUR_DIM * slots_count
    # Raw values into one array, then one division by the slot scales and one clip to the slot
    # bounds (as core.observation): absent slots stay exactly 0.
    raw = xp.empty((batch, n_uav, local_observation_dim(k, m, nearest)), dtype=z.dtype, device=on)
    v = z[..., 3:]
    raw[..., 0:3] = v
    subtract_into(raw[..., 3:6], v, reference_velocity)
    raw[..., 6:9] = reference_velocity
    raw[..., 9:12] = estimate
    raw[..., 12] = time_fraction[:, None]
    raw[..., 13] = avoiding
    raw[..., 14] = min_separation
    raw[..., 15:18] = reference_velocity if next_velocity is None else next_velocity[:, None]
    raw[..., 18] = 0.0 if time_to_switch is None else time_to_switch[:, None]

    # neighbour slots, then proximity slots
    if distance is None:
        distance = pair_distances(z[..., :3])
    candidates = _candidates(distance, adjacency, z[..., :3], sensing_radius)
    neighbour_index = _select_slots(candidates, k, nearest)
    present = neighbour_index >= 0
    safe = xp.where(present, neighbour_index, 0)
    flat = safe + (xp.arange(batch, device=on) * n_uav)[:, None, None]  # into the (B·N) rows
    a = anchored(z, offsets)  # (B, N, 6)
    # a view: reshape splits raw's contiguous last axis (on both libraries)
    slots = raw[..., OWN_DIM:end].reshape((batch, n_uav, slots_count, NEIGHBOUR_DIM))
    slots[..., 0] = present
    slots[..., 1] = (_take_rows(adjacency, safe) != 0) & present
    subtract_into(slots[..., 2:5], z[..., :3].reshape((-1, 3))[flat], z[:, :, None, :3])
    subtract_into(slots[..., 5:11], a.reshape((-1, 6))[flat], a[:, :, None])
    slots[~present] = 0.0

    # obstacle slots
    n_obs = obstacle_radii.shape[1]
    obstacles = raw[..., end:].reshape((batch, n_uav, m, OBSTACLE_DIM))  # a view
    obstacles[...] = 0.0
    if n_obs and m:
        # padding may hold any centre (1e12, inf, NaN): zero it before any arithmetic
        centres = xp.where(obstacle_present[..., None], obstacle_centers, 0.0)  # (B, O, 2)
        radii = xp.where(obstacle_present, obstacle_radii, 0.0)[:, None]  # (B, 1, O)
        rel = centres[:, None] - z[:, :, None, :2]  # (B, N, O, 2)
        surface = xp.sqrt(einsum_in(xp, "bnok,bnok->bno", rel, rel)) - radii  # (B, N, O)
        # absent (and non-finite) obstacles sort last and leave their slot absent
        usable = obstacle_present[:, None] & xp.isfinite(surface)
        order = _k_smallest(xp.where(usable, surface, xp.inf), m)  # (B, N, min(m, O))
        used = _take_rows(usable, order)
        taken = obstacles[..., : order.shape[-1], :]
        taken[..., 0] = used
        rows = xp.arange(batch * n_uav, device=on) * n_obs
        pick = order + rows.reshape((batch, n_uav, 1))
        taken[..., 1:3] = rel.reshape((-1, 2))[pick]
        taken[..., 3] = _take_rows(xp.broadcast_to(radii, surface.shape), order)
        taken[..., 4] = surface.reshape((-1,)).take(pick)
        taken[~used] = 0.0

    raw /= scale
    clip_in_place(raw, low, high)
    obs = raw.astype(np.float32) if numpy else xp.astype(raw, xp.float32)
    return LocalObservations(obs=obs, neighbour_index=neighbour_index)


@dataclass(frozen=True)
class DecodedLocalObservation:
    """Physical quantities recovered from local observations, leading dims (...) of the input."""

    velocity: np.ndarray  # (..., 3) [m/s]
    velocity_error: np.ndarray  # (..., 3) v - v^d [m/s]
    reference_velocity: np.ndarray  # (..., 3) [m/s]
    estimate: np.ndarray  # (..., 3) [m/s^2]
    time_fraction: np.ndarray  # (...)
    avoiding: np.ndarray  # (...) bool
    nearest_distance: np.ndarray  # (...) nearest other UAV [m] (clipped at 1000 m)
    next_velocity: np.ndarray  # (..., 3) [m/s]
    time_to_switch: np.ndarray  # (...) [s] (clipped at 500 s)
    # UAV slots: S = k neighbour slots, then the proximity slots
    slot_present: np.ndarray  # (..., S) bool
    neighbour: np.ndarray  # (..., S) bool, h_ij of the UAV in each slot
    relative_position: np.ndarray  # (..., S, 3) p_j - p_i [m] (clipped at ±1000 m)
    relative_formation_error: np.ndarray  # (..., S, 6) a_j - a_i [m, m/s]
    obstacle_present: np.ndarray  # (..., m) bool
    obstacle_relative: np.ndarray  # (..., m, 2) centre - own position [m] (clipped at ±1000 m)
    obstacle_radius: np.ndarray  # (..., m) [m]
    obstacle_surface: np.ndarray  # (..., m) [m] (clipped at ±1000 m)
    # (..., k) the UAV in each slot, -1 where absent: communication metadata that comes with the
    # observation (whose broadcast plan is whose), None if not given
    neighbour_index: np.ndarray | None = None


def decode_local_observations(
    obs: np.ndarray,
    k: int = 4,
    m: int = 2,
    nearest: int = 2,
    *,
    neighbour_index: np.ndarray | None = None,
) -> DecodedLocalObservation:
    """Undo the scaling of :func:`build_local_observations` (the unclipped slots exactly).

    numpy or torch: the decoded arrays are float64 in the library and on the device of ``obs``
    (a torch ``neighbour_index`` stays a tensor there too).

    Neighbour and proximity slots decode alike: the UAV slot arrays have k + nearest entries.

    Args:
        obs: (..., dim) observations.
        k: neighbour slots they were built with.
        m: obstacle slots they were built with.
        nearest: proximity slots they were built with.
        neighbour_index: (..., k + nearest) ints, :attr:`LocalObservations.neighbour_index` of
            the same step (kept as given; needed by policies that exchange plans).
    """
    dim = local_observation_dim(k, m, nearest)
    obs = as_float(obs)
    xp = namespace_of(obs)
    if not is_numpy(xp):
        obs = xp.astype(obs, xp.float64)
    if obs.shape[-1] not in (dim, dim + ROUTE_SLOTS):
        raise ValueError(
            f"expected a last axis of {dim} (k={k}, m={m}, nearest={nearest}), or "
            f"{dim + ROUTE_SLOTS} with the route slots, got {tuple(obs.shape)}"
        )
    obs = obs[..., :dim]  # the route slots (observation.route_offset) are not decoded
    lead = tuple(obs.shape[:-1])
    slots = k + nearest
    end = OWN_DIM + NEIGHBOUR_DIM * slots
    nb = obs[..., OWN_DIM:end].reshape(*lead, slots, NEIGHBOUR_DIM)
    ob = obs[..., end:].reshape(*lead, m, OBSTACLE_DIM)
    relative = xp.concat((nb[..., 5:8] * FORMATION_SCALE, nb[..., 8:11] * VELOCITY_SCALE), axis=-1)
    return DecodedLocalObservation(
        velocity=obs[..., 0:3] * VELOCITY_SCALE,
        velocity_error=obs[..., 3:6] * VELOCITY_SCALE,
        reference_velocity=obs[..., 6:9] * VELOCITY_SCALE,
        estimate=obs[..., 9:12] * ESTIMATE_SCALE,
        time_fraction=obs[..., 12],
        avoiding=obs[..., 13] > 0.5,
        nearest_distance=obs[..., 14] * DISTANCE_SCALE,
        next_velocity=obs[..., 15:18] * VELOCITY_SCALE,
        time_to_switch=obs[..., 18] * TIME_SCALE,
        slot_present=nb[..., 0] > 0.5,
        neighbour=nb[..., 1] > 0.5,
        relative_position=nb[..., 2:5] * DISTANCE_SCALE,
        relative_formation_error=relative,
        obstacle_present=ob[..., 0] > 0.5,
        obstacle_relative=ob[..., 1:3] * DISTANCE_SCALE,
        obstacle_radius=ob[..., 3] * DISTANCE_SCALE,
        obstacle_surface=ob[..., 4] * DISTANCE_SCALE,
        neighbour_index=(
            None if neighbour_index is None else _checked_index(neighbour_index, obs, slots)
        ),
    )


def _checked_index(neighbour_index: Any, obs: Any, k: int) -> Any:
    """``neighbour_index`` as int64 in the library and on the device of ``obs``, shape-checked."""
    expected = (*obs.shape[:-1], k)
    if isinstance(obs, np.ndarray):
        index = np.asarray(neighbour_index)
        integral = index.dtype.kind in "iu"
    else:
        xp = namespace_of(obs)
        index = xp.asarray(neighbour_index, device=device(obs))
        integral = xp.isdtype(index.dtype, "integral")
    if tuple(index.shape) != expected or not integral:
        raise ValueError(
            f"neighbour_index must be integers of shape {expected}, got {index.dtype} "
            f"{tuple(index.shape)}"
        )
    return index.astype(np.int64) if isinstance(index, np.ndarray) else index.long()


ABSENT_DISTANCE = 1e6  # where an absent slot's UAV is put in a slot frame: never within reach [m]


@dataclass(frozen=True)
class SlotFrame:
    """UAV i's own-frame picture of the UAVs in its slots, from its local observation alone.

    The frame puts UAV i at position 0 with formation offset 0; the UAV in slot s then has the
    state ``(p_j - p_i, v_i + (a_j - a_i)_v)`` and the offset ``z_j - a_j`` relative to i's, so
    that anchored differences ``a_j - a_i`` and relative positions are exactly the observed ones
    (velocities exactly when the formation's velocity offsets are equal, as in every shape of
    :mod:`uav_formation_env.formations`). Absent slots sit at :data:`ABSENT_DISTANCE`.

    Attributes:
        own: (..., 6) UAV i's state: position 0, own velocity [m, m/s].
        slots: (..., k, 6) the slots' states [m, m/s].
        slot_offsets: (..., k, 6) the slots' formation offsets relative to UAV i's [m, m/s].
        adjacency: (..., k) h_ij of the UAV in each slot (0 where absent).
        present: (..., k) 1 where the slot holds a UAV.
    """

    own: np.ndarray
    slots: np.ndarray
    slot_offsets: np.ndarray
    adjacency: np.ndarray
    present: np.ndarray


def slot_frame(decoded: DecodedLocalObservation) -> SlotFrame:
    """The :class:`SlotFrame` of decoded local observations (leading dims kept; numpy or
    torch, the library of the decoded arrays)."""
    velocity = decoded.velocity
    xp = namespace_of(velocity)
    own = xp.concat((xp.zeros_like(velocity), velocity), axis=-1)
    present = decoded.slot_present
    error = decoded.relative_formation_error  # (..., k, 6) a_j - a_i
    position = xp.where(present[..., None], decoded.relative_position, ABSENT_DISTANCE)
    slots = xp.concat((position, velocity[..., None, :] + error[..., 3:]), axis=-1)
    slot_offsets = xp.zeros_like(slots)
    slot_offsets[..., :3] = position - error[..., :3]
    return SlotFrame(
        own=own,
        slots=slots,
        slot_offsets=slot_offsets,
        adjacency=xp.astype(decoded.neighbour & present, velocity.dtype),
        present=xp.astype(present, velocity.dtype),
    )


# slots appended by ``observation.route_offset``: UAV i's offset from its slot on the preset route,
# horizontal (x, y) / 100 m, clipped ±10 (episode.route_offsets)
ROUTE_SLOTS = 2


def observation_size(scenario: Scenario, n_uav: int | None = None) -> int:
    """Length of one agent's observation under ``scenario.observation`` ("full": the layout of
    :mod:`uav_formation_env.core.observation` for N UAVs, the scenario's N if None; "local":
    this module's, whatever N)."""
    config = scenario.observation
    route = ROUTE_SLOTS if config.route_offset else 0
    if config.kind == "local":
        return local_observation_dim(config.neighbours, config.obstacles, config.nearest) + route
    return observation_dim(scenario.n_uav if n_uav is None else n_uav) + route


def observation_bounds(scenario: Scenario, n_uav: int | None = None) -> tuple[np.ndarray, ...]:
    """(dim,) float32 lower and upper bounds of every observation slot."""
    config = scenario.observation
    if config.kind == "local":
        low, high = local_observation_bounds(config.neighbours, config.obstacles, config.nearest)
        if config.route_offset:
            clip = np.full(ROUTE_SLOTS, DISTANCE_CLIP, dtype=np.float32)
            low, high = np.concatenate((low, -clip)), np.concatenate((high, clip))
        return low, high
    dim = observation_size(scenario, n_uav)
    bound = np.full(dim, OBSERVATION_BOUND, dtype=np.float32)
    return -bound, bound
