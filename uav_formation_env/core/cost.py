"""The game cost J_i (eq. 6, SPEC §4): one definition behind the env reward and the MPC objective.

For UAV i over a horizon of H steps, with ``ε_ij(k) = (z_i(k) - z^d_i) - (ẑ_j(k) - z^d_j)``:

    J_i = q Σ_j h_ij Σ_{k<H} ||ε_ij(k)||² + r Σ_{k<H} ||u_i(k)||²
        + m Σ_j h_ij ||ε_ij(H)||² + n Σ_{k<=H} ||v_i(k) - v^d_i(k)||²

``||x||_w`` is read as ``w xᵀx`` (SPEC §4.1). The stage cost, the reward of one realised transition,
is the ``k``-th summand: ``q Σ_j h_ij ||ε_ij||² + r ||u_i||² + n ||v_i - v^d_i||²``. Both are built
from the same two term functions below.

Shapes: B scenario copies, N UAVs, P candidates per UAV, H horizon steps.
"""

from __future__ import annotations

from dataclasses import dataclass

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

    @property
    def total(self) -> np.ndarray:
        return self.formation + self.energy + self.terminal + self.velocity

    def as_dict(self) -> dict[str, np.ndarray]:
        return {
            "formation": self.formation,
            "energy": self.energy,
            "terminal": self.terminal,
            "velocity": self.velocity,
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


def formation_error_sq(own: np.ndarray, others: np.ndarray, adjacency: np.ndarray) -> np.ndarray:
    """``Σ_j h_ij ||own_i - others_j||²`` for anchored states, without forming all pairs.

    Expands the square as ``deg_i ||a_i||² - 2 a_i·Σ_j h_ij b_j + Σ_j h_ij ||b_j||²`` after moving
    both sides to the swarm's centre (per copy), so no terms of the size of absolute positions
    (hundreds of metres) cancel.

    Args:
        own: (B, N, *extra, 6) receivers' anchored states, e.g. extra = (P, H+1).
        others: (B, N, *tail, 6) senders' anchored states, where ``tail`` are the trailing dims of
            ``extra`` (e.g. (H+1,)), or ``()``.
        adjacency: (B, N, N) h_ij, row = receiver.

    Returns:
        (B, N, *extra).
    """
    batch, n_uav = others.shape[:2]
    extra, tail = own.ndim - 3, others.ndim - 3
    centre = others.reshape(batch, n_uav, -1, 6)[:, :, 0].mean(axis=1)  # (B, 6)
    a = own - centre.reshape(batch, 1, *(1,) * extra, 6)
    b = others - centre.reshape(batch, 1, *(1,) * tail, 6)
    degree = adjacency.sum(axis=-1).reshape(batch, n_uav, *(1,) * extra)
    h_b = np.einsum("bij,bj...->bi...", adjacency, b)  # (B, N, *tail, 6)
    h_bb = np.einsum("bij,bj...->bi...", adjacency, np.einsum("...k,...k->...", b, b))
    lead = (slice(None), slice(None)) + (None,) * (extra - tail)
    return (
        degree * np.einsum("...k,...k->...", a, a)
        - 2.0 * np.einsum("...k,...k->...", a, h_b[lead])
        + h_bb[lead]
    )


def velocity_error_sq(velocity: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``||v - v^d||²`` over the last axis; shapes broadcast, (..., 3) -> (...)."""
    diff = velocity - reference
    return np.einsum("...k,...k->...", diff, diff)


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
        weights: q, r, n (the terminal weight m does not enter a stage).
        mirrored: literal mirrored-offset reading.

    Returns:
        :class:`CostTerms` of shape (B, N) with ``terminal = 0``.
    """
    a = anchored(z, offsets, mirrored)
    formation = weights.q * formation_error_sq(a, a, adjacency)
    return CostTerms(
        formation=formation,
        energy=weights.r * np.einsum("...k,...k->...", u_n, u_n),
        terminal=np.zeros_like(formation),
        velocity=weights.n * velocity_error_sq(z[..., 3:], reference_velocity),
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
        neighbour_trajectories: (B, N, H+1, 6) each UAV's broadcast prediction ẑ_j(k), k = 0..H.
        reference_preview: (B, N, H+1, 3) v^d_i(t + kδ) [m/s].
        adjacency: (B, N, N) h_ij, row = receiver.
        offsets: (N, 6) z^d.
        weights: q, r, m, n.
        dt: control step δ [s].
        mirrored: literal mirrored-offset reading.

    Returns:
        :class:`CostTerms` of shape (B, N, P).
    """
    predicted = rollout(z0[:, :, None, :], candidates, dt)  # (B, N, P, H+1, 6)
    own = anchored(predicted, offsets, mirrored)
    others = anchored(neighbour_trajectories, offsets, mirrored)
    pair_sq = formation_error_sq(own, others, adjacency)  # (B, N, P, H+1)
    velocity_sq = velocity_error_sq(predicted[..., 3:], reference_preview[:, :, None])
    return CostTerms(
        formation=weights.q * pair_sq[..., :-1].sum(axis=-1),
        energy=weights.r * np.einsum("...hk,...hk->...", candidates, candidates),
        terminal=weights.m * pair_sq[..., -1],
        velocity=weights.n * velocity_sq.sum(axis=-1),
    )
