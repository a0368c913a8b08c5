"""A cheap sanity controller: linear consensus PD toward the formation slots and the reference.

For UAV i with anchored states ``a = z - z^d`` (so the formation is ``a_i = a_j``):

    u_i = -k_p Σ_j h_ij (a_i - a_j)_pos - k_d Σ_j h_ij (v_i - v_j) - k_v (v_i - v^d_i)
          + k_s Σ_{j: d_ij < R} (R - d_ij) (p_i - p_j) / d_ij

clipped to ±u_max. The last term is a short-range separation (over every UAV within R, not only
neighbours): from random initial positions the slots are reached along crossing paths. It uses
only what UAV i senses or receives (the states of its neighbours and of UAVs nearby, its reference
velocity) and needs no optimiser, so it runs the whole scenario in milliseconds; tests and
``uav-formation run`` use it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uav_formation_env.core.cost import anchored


@dataclass(frozen=True)
class ConsensusGains:
    """Gains of the consensus PD law."""

    position: float = 0.08  # k_p, relative formation position error [1/s^2]
    velocity: float = 0.4  # k_d, relative velocity [1/s]
    reference: float = 1.0  # k_v, own velocity error to v^d [1/s]
    separation: float = 1.0  # k_s, push away from UAVs closer than separation_radius [1/s^2]
    separation_radius: float = 8.0  # R [m]

    def __post_init__(self) -> None:
        for name in ("position", "velocity", "reference", "separation", "separation_radius"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"invalid gain '{name}': must be finite and >= 0, got {value!r}")


def consensus_pd(
    z: np.ndarray,
    reference_velocity: np.ndarray,
    adjacency: np.ndarray,
    offsets: np.ndarray,
    u_max: float,
    gains: ConsensusGains = ConsensusGains(),
) -> np.ndarray:
    """Consensus PD input of every UAV.

    Args:
        z: (B, N, 6) states [m, m/s].
        reference_velocity: (B, N, 3) v^d [m/s].
        adjacency: (B, N, N) h_ij, row = receiver.
        offsets: (N, 6) formation offsets z^d.
        u_max: per-axis bound [m/s^2].
        gains: the PD gains.

    Returns:
        (B, N, 3) formation input u_n [m/s^2].
    """
    a = anchored(z, offsets)
    degree = adjacency.sum(axis=-1, keepdims=True)
    disagreement = degree * a - np.einsum("bij,bjk->bik", adjacency, a)  # Σ_j h_ij (a_i - a_j)
    u = (
        -gains.position * disagreement[..., :3]
        - gains.velocity * disagreement[..., 3:]
        - gains.reference * (z[..., 3:] - reference_velocity)
    )
    if gains.separation > 0:
        diff = z[:, :, None, :3] - z[:, None, :, :3]  # p_i - p_j, (B, N, N, 3)
        dist = np.sqrt(np.einsum("bijk,bijk->bij", diff, diff))
        push = np.clip(gains.separation_radius - dist, 0.0, None) / np.maximum(dist, 1e-6)
        push[:, np.arange(z.shape[1]), np.arange(z.shape[1])] = 0.0
        u = u + gains.separation * np.einsum("bij,bijk->bik", push, diff)
    return np.clip(u, -u_max, u_max)
