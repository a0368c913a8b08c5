"""The terms of J_i and the stage cost of one realised transition (the env's -reward).

Array-API functions: numpy arrays or torch tensors (core/array_api.py); the results are in the
inputs' library, dtype and device.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from types import ModuleType
from typing import Any

import numpy as np

from uav_formation_env.config import CostConfig
from uav_formation_env.core.array_api import (
    asarray_like,
    device,
    einsum_function,
    einsum_in,
    is_numpy,
    namespace_of,
    read_only,
)
from uav_formation_env.core.proximity import SensedPairs, gap_sq, pair_distances


@dataclass(frozen=True)
class CostTerms:
    """Named, already weighted terms of J_i, each of the same shape (e.g. (B, N) or (B, N, P)),
    numpy arrays or torch tensors."""

    formation: np.ndarray  # q Σ_j h_ij Σ_k ||ε_ij(k)||²
    energy: np.ndarray  # r Σ_k ||u_i(k)||²
    terminal: np.ndarray  # m Σ_j h_ij ||ε_ij(H)||²
    velocity: np.ndarray  # n Σ_k ||v_i(k) - v^d_i(k)||²
    separation: np.ndarray  # s Σ_{j≠i} Σ_k max(0, d_s - ||p_i(k) - p_j(k)||)²
    obstacle: np.ndarray  # o Σ_obstacles Σ_k max(0, R + c_o - D_i(k))² (horizontal D)

    @property
    def total(self) -> np.ndarray:
        return (
            self.formation
            + self.energy
            + self.terminal
            + self.velocity
            + self.separation
            + self.obstacle
        )

    def as_dict(self) -> dict[str, np.ndarray]:
        return {
            "formation": self.formation,
            "energy": self.energy,
            "terminal": self.terminal,
            "velocity": self.velocity,
            "separation": self.separation,
            "obstacle": self.obstacle,
        }


def anchored(z: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """States relative to each UAV's formation slot, ``z - z^d``.

    Args:
        z: (B, N, *extra, 6) states [m, m/s], numpy or torch.
        offsets: (N, 6) formation offsets z^d shared by every copy, or (B, N, 6) one shape per
            copy (scene distributions draw the formation per reset); the library of ``z``.
            (The literal mirrored reading of the paper arrives here as negated offsets:
            :attr:`~uav_formation_env.config.FormationConfig.slot_offsets`.)
    """
    extra = z.ndim - 3
    zd = offsets.reshape(*offsets.shape[:-1], *(1,) * extra, 6)
    return z - zd


@dataclass(frozen=True)
class NeighbourMoments:
    """The sender side of ``Σ_j h_ij ||a_i - b_j||²``, summed once for any number of ``a_i``.

    Both sides are moved to a centre per copy (per receiver for per-receiver views) first, so that
    no terms of the size of absolute positions (hundreds of metres) cancel.

    Attributes:
        centre: (B, R, 6) the shift subtracted from both sides (None in the moments
            :func:`formation_error_sq` builds for receivers that are the senders, never returned).
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
        extra = own.ndim - 3
        a = own - self.centre.reshape(batch, n_recv, *(1,) * extra, 6)
        return self.centred_error_sq(a, einsum_in(namespace_of(a), "...k,...k->...", a, a))

    def centred_error_sq(self, a: np.ndarray, a_sq: np.ndarray) -> np.ndarray:
        """:meth:`error_sq` from the receivers' centred states ``a = own - centre`` and ``||a||²``.

        Args:
            a: (B, R, *extra, 6) receivers' anchored states minus :attr:`centre`.
            a_sq: (B, R, *extra) ``einsum("...k,...k->...", a, a)``, e.g. already computed for the
                senders' side when receivers and senders are the same states.

        Returns:
            (B, R, *extra).
        """
        xp = namespace_of(a)
        batch, n_recv = self.degree.shape
        extra, tail = a.ndim - 3, self.h_b.ndim - 3
        degree = self.degree.reshape(batch, n_recv, *(1,) * extra)
        lead = (slice(None), slice(None)) + (None,) * (extra - tail)
        a_h_b = einsum_in(xp, "...k,...k->...", a, self.h_b[lead])
        return degree * a_sq - 2.0 * a_h_b + self.h_bb[lead]

    def take(self, index: np.ndarray) -> NeighbourMoments:
        """The receivers ``index`` of the flattened (B·R) axis, as one copy: shapes (1, M, ...)."""
        return NeighbourMoments(*(take_flat(x, index) for x in self._fields()))

    def _fields(self) -> tuple[np.ndarray, ...]:
        return self.centre, self.degree, self.h_b, self.h_bb


def take_flat(x: np.ndarray, index: np.ndarray) -> np.ndarray:
    """Rows ``index`` of ``x`` with its first two axes (B, R) flattened, as (1, M, ...) (numpy or
    torch; ``index`` an integer or boolean array of the same library)."""
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
    return _moments_and_centred(others, adjacency, per_receiver)[0]


def _moments_and_centred(
    others: np.ndarray, adjacency: np.ndarray, per_receiver: bool, with_centre: bool = True
) -> tuple[NeighbourMoments, np.ndarray, np.ndarray]:
    """:func:`neighbour_moments`, plus the centred senders ``b`` and ``||b||²`` it summed.

    ``with_centre=False`` (one view of the senders only) leaves :attr:`NeighbourMoments.centre`
    None, for :meth:`~NeighbourMoments.centred_error_sq`, which does not need it (saves the
    (B, R, 6) copy).
    """
    xp = namespace_of(others)
    einsum = einsum_function(xp)
    if not is_numpy(xp):
        adjacency = asarray_like(adjacency, others)  # e.g. the config's, as numpy
    batch, n_recv = adjacency.shape[:2]
    if per_receiver:
        tail = others.ndim - 4
        first = others.reshape(batch, n_recv, others.shape[2], -1, 6)[:, :, :, 0]
        centre = xp.mean(first, axis=2)  # (B, R, 6)
        b = others - centre.reshape(batch, n_recv, 1, *(1,) * tail, 6)
        spec = "bij,bij...->bi..."
    else:
        tail = others.ndim - 3
        first = others.reshape(batch, others.shape[1], -1, 6)[:, :, 0] if tail else others
        # first.mean(axis=1) is this reduction and division, behind two Python wrappers
        mean = _sum(xp, first, axis=1) / first.shape[1]  # (B, 6)
        centre = _repeat(xp, mean[:, None], n_recv, axis=1) if with_centre else None  # (B, R, 6)
        b = others - mean.reshape(batch, 1, *(1,) * tail, 6)
        spec = "bij,bj...->bi..."
    b_sq = einsum("...k,...k->...", b, b)
    moments = NeighbourMoments(
        centre=centre,
        degree=_sum(xp, adjacency, axis=-1),
        h_b=einsum(spec, adjacency, b),
        h_bb=einsum(spec, adjacency, b_sq),
    )
    return moments, b, b_sq


def _sum(xp: ModuleType, x: Any, axis: int) -> Any:
    """``xp.sum(x, axis=axis)``; numpy's ufunc reduction directly (the same pairwise sum: np.sum
    wraps it in a Python layer)."""
    return np.add.reduce(x, axis=axis) if is_numpy(xp) else xp.sum(x, axis=axis)


def _repeat(xp: ModuleType, x: Any, repeats: int, axis: int) -> Any:
    """``xp.repeat``; numpy's method directly (np.repeat adds a Python layer)."""
    return x.repeat(repeats, axis=axis) if is_numpy(xp) else xp.repeat(x, repeats, axis=axis)


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
    # the stage cost's case: receivers are the senders, centred alike (the same numbers)
    same = own is others and not per_receiver
    moments, centred, centred_sq = _moments_and_centred(others, adjacency, per_receiver, not same)
    if same:
        return moments.centred_error_sq(centred, centred_sq)
    return moments.error_sq(own)


def velocity_error_sq(velocity: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``||v - v^d||²`` over the last axis; shapes broadcast, (..., 3) -> (...) (numpy or torch)."""
    diff = velocity - reference
    return einsum_in(namespace_of(diff), "...k,...k->...", diff, diff)


def separation_active(weights: CostConfig) -> bool:
    """Whether the separation term can be non-zero (``s > 0`` and ``d_s > 0``)."""
    return weights.separation > 0.0 and weights.separation_distance > 0.0


def obstacle_active(weights: CostConfig) -> bool:
    """Whether the obstacle term can be non-zero (``o > 0``; with a zero margin it still acts
    inside an obstacle)."""
    return weights.obstacle > 0.0


def obstacle_sq(surface: np.ndarray, margin: float) -> np.ndarray:
    """``max(0, c_o - surface)²``, the unweighted obstacle penalty of a UAV whose horizontal
    distance to an obstacle's surface is ``surface`` (D - R, negative inside) [m²]; numpy or
    torch, any shape (+inf, no obstacle: 0)."""
    return gap_sq(surface, margin)


@lru_cache(maxsize=16)
def _not_eye(n_uav: int) -> np.ndarray:
    """(N, N) ``1 - I``, cached and read-only."""
    mask = 1.0 - np.eye(n_uav)
    read_only(mask)
    return mask


def _not_eye_like(n_uav: int, like: Any) -> Any:
    """:func:`_not_eye` in the library, dtype and device of ``like`` (the cached array itself for
    numpy; for torch a new ``1 - I``, the same 0/1 values, without sharing the read-only cache)."""
    xp = namespace_of(like)
    if is_numpy(xp):
        return _not_eye(n_uav)
    return 1.0 - xp.eye(n_uav, dtype=like.dtype, device=device(like))


def others_mask(batch: int, n_uav: int, like: Any = None) -> np.ndarray:
    """(B, N, N) 1 for every other UAV j of receiver i, 0 on the diagonal (read-only view).

    ``like``: an array whose library, dtype and device the mask takes (a float torch tensor for a
    torch mask); the float64 numpy mask without it or for a numpy one.
    """
    if like is None:
        return np.broadcast_to(_not_eye(n_uav), (batch, n_uav, n_uav))
    xp = namespace_of(like)
    return xp.broadcast_to(_not_eye_like(n_uav, like), (batch, n_uav, n_uav))


def separation_sq(
    own: np.ndarray, others: np.ndarray, mask: np.ndarray, distance: float
) -> np.ndarray:
    """``Σ_j mask_ij max(0, d_s - ||own_i - others_ij||)²``: the unweighted separation penalty.

    Args:
        own: (B, R, *extra, 3) receivers' positions [m], e.g. extra = (P, H+1); numpy or torch.
        others: (B, R, S, *tail, 3) each receiver's view of every sender's positions [m], where
            ``tail`` are the trailing dims of ``extra`` (e.g. (H+1,)) or ``()``.
        mask: (B, R, S) which senders count (0 for the receiver itself).
        distance: d_s [m].

    Returns:
        (B, R, *extra) [m²].
    """
    xp = namespace_of(own)
    if not is_numpy(xp):
        mask = asarray_like(mask, own)  # e.g. the numpy others_mask
    batch, n_recv, n_send = mask.shape
    tail = others.ndim - 4
    lead = own.ndim - 3 - tail
    own = own.reshape(*own.shape[: 2 + lead], 1, *own.shape[2 + lead :])
    others = others.reshape(batch, n_recv, *(1,) * lead, *others.shape[2:])
    diff = own - others  # (B, R, *lead, S, *tail, 3)
    pair = xp.sqrt(einsum_in(xp, "...k,...k->...", diff, diff))
    weight = mask.reshape(batch, n_recv, *(1,) * lead, n_send, *(1,) * tail)
    return _gap_sq_sum(pair, weight, distance, 2 + lead)


def _gap_sq_sum(pair: np.ndarray, weight: np.ndarray, distance: float, axis: int) -> np.ndarray:
    """``Σ_axis weight max(0, d_s - pair)²`` of pair distances [m] (shapes broadcast) [m²]."""
    weighted = gap_sq(pair, distance) * weight
    return _sum(namespace_of(weighted), weighted, axis=axis)


def stage_cost(
    z: np.ndarray,
    u_n: np.ndarray,
    reference_velocity: np.ndarray,
    adjacency: np.ndarray,
    offsets: np.ndarray,
    weights: CostConfig,
    pair_distance: np.ndarray | SensedPairs | None = None,
    obstacle_surface: np.ndarray | None = None,
) -> CostTerms:
    """One summand of J_i on realised states (the env reward is minus its total).

    Takes numpy arrays or torch tensors (``z``, ``u_n``, ``reference_velocity`` of one library;
    on torch, ``adjacency``, ``offsets`` and a ``pair_distance`` matrix may also come as numpy,
    e.g. from the config, and are moved to ``z``'s dtype and device).

    Args:
        z: (B, N, 6) states [m, m/s].
        u_n: (B, N, 3) formation input (without the compensation u_d) [m/s^2].
        reference_velocity: (B, N, 3) v^d [m/s].
        adjacency: (B, N, N) h_ij.
        offsets: (N, 6) z^d shared by every copy, or (B, N, 6) one shape per copy [m, m/s].
        weights: q, r, n, s, d_s (the terminal weight m does not enter a stage).
        pair_distance: (B, N, N) :func:`pair_distances` of ``z``'s positions [m], if the caller
            has them already, or the (numpy)
            :class:`~uav_formation_env.core.proximity.SensedPairs` within a sensing radius >= d_s
            (the same term, linear in N); computed here otherwise (only when the separation term
            is on).
        obstacle_surface: (B, N) horizontal distance of each UAV to the nearest obstacle's
            surface [m] (negative inside, +inf without obstacles), in ``z``'s library; None: no
            obstacle (the term is 0, as it is with ``cost.obstacle = 0``). Safety circles
            never overlap (configuration rule), so with ``obstacle_margin`` at most the safety
            margin at most one obstacle, the nearest, has a non-zero term at any position: the
            nearest one's term is the sum over all of them.

    Returns:
        :class:`CostTerms` of shape (B, N) with ``terminal = 0``, in ``z``'s library and device;
        ``separation`` runs over every other UAV, whatever the adjacency.
    """
    xp = namespace_of(z)
    if not is_numpy(xp):
        adjacency = asarray_like(adjacency, z)
        offsets = asarray_like(offsets, z)
        if isinstance(pair_distance, np.ndarray):
            pair_distance = asarray_like(pair_distance, z)
    a = anchored(z, offsets)
    formation = weights.q * formation_error_sq(a, a, adjacency)
    distance = weights.separation_distance
    active = separation_active(weights)
    if active and pair_distance is None:
        pair_distance = pair_distances(z[..., :3])
    # The penalty is exactly +0 while every pair is at least d_s apart (the usual case); NaN
    # distances fail the test and take the general path.
    # (on torch the general path always runs: the test would wait for the device, and the
    # general path's sum is the same exact +0 then)
    if active and isinstance(pair_distance, SensedPairs):
        separation = weights.separation * asarray_like(pair_distance.gap_sq_sum(distance), z)
    elif active and (not is_numpy(xp) or not pair_distance.min() >= distance):
        # the diagonal is +inf here (0 in separation_sq): either way its term is exactly +0
        not_eye = _not_eye_like(z.shape[1], pair_distance)
        gap_sq = _gap_sq_sum(pair_distance, not_eye, distance, axis=2)
        separation = weights.separation * gap_sq
    else:
        separation = xp.zeros(formation.shape, dtype=formation.dtype, device=device(formation))
    if obstacle_active(weights) and obstacle_surface is not None:
        obstacle = weights.obstacle * obstacle_sq(obstacle_surface, weights.obstacle_margin)
    else:
        obstacle = xp.zeros(formation.shape, dtype=formation.dtype, device=device(formation))
    return CostTerms(
        formation=formation,
        energy=weights.r * einsum_in(xp, "...k,...k->...", u_n, u_n),
        terminal=xp.zeros(formation.shape, dtype=formation.dtype, device=device(formation)),
        velocity=weights.n * velocity_error_sq(z[..., 3:], reference_velocity),
        separation=separation,
        obstacle=obstacle,
    )
