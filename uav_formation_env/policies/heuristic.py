"""A cheap sanity controller: linear consensus PD toward the formation slots and the reference.

For UAV i with anchored states ``a = z - z^d`` (so the formation is ``a_i = a_j``):

    u_i = -k_p Σ_j h_ij (a_i - a_j)_pos - k_d Σ_j h_ij (v_i - v_j) - k_v (v_i - v^d_i)

clipped to ±u_max. It uses only what UAV i senses or receives (its neighbours' states, its
reference velocity) and needs no optimiser, so it runs the whole scenario in milliseconds; tests and
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

    def __post_init__(self) -> None:
        for name in ("position", "velocity", "reference"):
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
    mirrored: bool = False,
) -> np.ndarray:
    """Consensus PD input of every UAV.

    Args:
        z: (B, N, 6) states [m, m/s].
        reference_velocity: (B, N, 3) v^d [m/s].
        adjacency: (B, N, N) h_ij, row = receiver.
        offsets: (N, 6) formation offsets z^d.
        u_max: per-axis bound [m/s^2].
        gains: the PD gains.
        mirrored: literal mirrored-offset reading of the formation.

    Returns:
        (B, N, 3) formation input u_n [m/s^2].
    """
    a = anchored(z, offsets, mirrored)
    degree = adjacency.sum(axis=-1, keepdims=True)
    disagreement = degree * a - np.einsum("bij,bjk->bik", adjacency, a)  # Σ_j h_ij (a_i - a_j)
    u = (
        -gains.position * disagreement[..., :3]
        - gains.velocity * disagreement[..., 3:]
        - gains.reference * (z[..., 3:] - reference_velocity)
    )
    return np.clip(u, -u_max, u_max)
