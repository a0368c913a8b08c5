"""The terms of J_i and the stage cost of one realised transition (the env's -reward)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uav_formation_env.config import CostConfig


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
        return NeighbourMoments(*(take_flat(x, index) for x in self._fields()))

    def _fields(self) -> tuple[np.ndarray, ...]:
        return self.centre, self.degree, self.h_b, self.h_bb


def take_flat(x: np.ndarray, index: np.ndarray) -> np.ndarray:
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


