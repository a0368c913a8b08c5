"""Per-agent observations: what UAV i senses or receives, at roughly unit scale.

Pure functions shared by the environment (encoding) and by policies acting from observations
(decoding), so both read one layout. Agent i's vector, with N UAVs (``dim = 19 + 7 (N - 1)``):

| slot | size | meaning | unit | scale |
|---|---|---|---|---|
| 0:3 | 3 | own velocity v_i | m/s | / 20 |
| 3:6 | 3 | velocity error to the reference, v_i - v^d_i | m/s | / 20 |
| 6:9 | 3 | reference velocity v^d_i | m/s | / 20 |
| 9:12 | 3 | disturbance estimate d̂_i + s0_i (0 with the observer off) | m/s^2 | / 0.5 |
| 12 | 1 | time t / duration | - | 1 |
| 13 | 1 | 1 if the reference is an avoidance reference (held over a horizon) | - | 1 |
| 14:16 | 2 | nearest obstacle centre minus own position, horizontal | m | / 100, clipped ±10 |
| 16 | 1 | distance to that obstacle's surface | m | / 100, clipped ±10 |
| 17 | 1 | 1 if the scenario has obstacles | - | 1 |
| 18 | 1 | distance to the nearest other UAV | m | / 100, clipped ±10 |
| 19 + 7k | 1 | neighbour flag h_ij for the k-th other UAV j (ascending j, skipping i) | - | 1 |
| 20 + 7k : 23 + 7k | 3 | relative formation position error (p_j - p^d_j)-(p_i - p^d_i) | m | / 50 |
| 23 + 7k : 26 + 7k | 3 | relative formation velocity error (v_j-v^d_j)-(v_i-v^d_i) | m/s | / 20 |

Every scaled value is clipped to ±100 (the space's bounds), reached only far off course.
Slots of the k-th other UAV are filled for every UAV (they are sensed, e.g. by radar); the flag says
whether UAV i receives messages from it (and so whether it enters J_i).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uav_formation_env.core.cost import anchored

VELOCITY_SCALE = 20.0  # [m/s]
ESTIMATE_SCALE = 0.5  # [m/s^2]
DISTANCE_SCALE = 100.0  # [m]
FORMATION_SCALE = 50.0  # [m]
DISTANCE_CLIP = 10.0  # clip of scaled distances [-]
OBSERVATION_BOUND = 100.0  # every scaled value is clipped to ±this (only reached far off course)
OWN_DIM = 19
OTHER_DIM = 7


def observation_dim(n_uav: int) -> int:
    """Length of one agent's observation vector."""
    return OWN_DIM + OTHER_DIM * (n_uav - 1)


def others_index(n_uav: int) -> np.ndarray:
    """(N, N-1) index of the k-th other UAV of each UAV (ascending, skipping itself)."""
    full = np.broadcast_to(np.arange(n_uav), (n_uav, n_uav))
    return full[~np.eye(n_uav, dtype=bool)].reshape(n_uav, n_uav - 1)


def build_observations(
    z: np.ndarray,
    reference_velocity: np.ndarray,
    estimate: np.ndarray,
    adjacency: np.ndarray,
    avoiding: np.ndarray,
    time_fraction: np.ndarray,
    offsets: np.ndarray,
    obstacle_centers: np.ndarray,
    obstacle_radii: np.ndarray,
    min_separation: np.ndarray,
    mirrored: bool = False,
) -> np.ndarray:
    """Every agent's observation.

    Args:
        z: (B, N, 6) states [m, m/s].
        reference_velocity: (B, N, 3) v^d [m/s].
        estimate: (B, N, 3) disturbance estimate [m/s^2].
        adjacency: (B, N, N) h_ij, row = receiver.
        avoiding: (B, N) bool.
        time_fraction: (B,) t / duration.
        offsets: (N, 6) formation offsets z^d.
        obstacle_centers: (O, 2) [m].
        obstacle_radii: (O,) [m].
        min_separation: (B, N) nearest other UAV [m].
        mirrored: literal mirrored-offset reading.

    Returns:
        (B, N, dim) float32.
    """
    batch, n_uav = z.shape[:2]
    v = z[..., 3:]
    own = np.zeros((batch, n_uav, OWN_DIM))
    own[..., 0:3] = v / VELOCITY_SCALE
    own[..., 3:6] = (v - reference_velocity) / VELOCITY_SCALE
    own[..., 6:9] = reference_velocity / VELOCITY_SCALE
    own[..., 9:12] = estimate / ESTIMATE_SCALE
    own[..., 12] = time_fraction[:, None]
    own[..., 13] = avoiding
    if len(obstacle_radii):
        rel = obstacle_centers[None, None] - z[:, :, None, :2]  # (B, N, O, 2)
        centre_dist = np.sqrt(np.einsum("bnok,bnok->bno", rel, rel))
        nearest = (centre_dist - obstacle_radii).argmin(axis=-1)  # (B, N)
        rows, cols = np.indices(nearest.shape)
        pick = rel[rows, cols, nearest]  # (B, N, 2)
        surface = centre_dist[rows, cols, nearest] - obstacle_radii[nearest]
        own[..., 14:16] = np.clip(pick / DISTANCE_SCALE, -DISTANCE_CLIP, DISTANCE_CLIP)
        own[..., 16] = np.clip(surface / DISTANCE_SCALE, -DISTANCE_CLIP, DISTANCE_CLIP)
        own[..., 17] = 1.0
    own[..., 18] = np.clip(min_separation / DISTANCE_SCALE, -DISTANCE_CLIP, DISTANCE_CLIP)

    a = anchored(z, offsets, mirrored)  # (B, N, 6)
    index = others_index(n_uav)  # (N, N-1)
    relative = a[:, index] - a[:, :, None]  # (B, N, N-1, 6)
    other = np.empty((batch, n_uav, n_uav - 1, OTHER_DIM))
    other[..., 0] = adjacency[:, np.arange(n_uav)[:, None], index]
    other[..., 1:4] = relative[..., :3] / FORMATION_SCALE
    other[..., 4:7] = relative[..., 3:] / VELOCITY_SCALE
    flat = np.concatenate((own, other.reshape(batch, n_uav, -1)), axis=-1)
    return np.clip(flat, -OBSERVATION_BOUND, OBSERVATION_BOUND).astype(np.float32)


@dataclass(frozen=True)
class DecodedObservation:
    """Physical quantities recovered from observations, leading dims (...) of the input."""

    velocity: np.ndarray  # (..., 3) [m/s]
    reference_velocity: np.ndarray  # (..., 3) [m/s]
    estimate: np.ndarray  # (..., 3) [m/s^2]
    time_fraction: np.ndarray  # (...)
    avoiding: np.ndarray  # (...) bool
    neighbour: np.ndarray  # (..., N-1) bool, h_ij of the k-th other UAV
    relative_formation_error: np.ndarray  # (..., N-1, 6) a_j - a_i [m, m/s]


def decode_observations(obs: np.ndarray, n_uav: int) -> DecodedObservation:
    """Undo the scaling of :func:`build_observations` (the unclipped slots exactly)."""
    obs = np.asarray(obs, dtype=float)
    other = obs[..., OWN_DIM:].reshape(*obs.shape[:-1], n_uav - 1, OTHER_DIM)
    relative = np.concatenate(
        (other[..., 1:4] * FORMATION_SCALE, other[..., 4:7] * VELOCITY_SCALE), axis=-1
    )
    return DecodedObservation(
        velocity=obs[..., 0:3] * VELOCITY_SCALE,
        reference_velocity=obs[..., 6:9] * VELOCITY_SCALE,
        estimate=obs[..., 9:12] * ESTIMATE_SCALE,
        time_fraction=obs[..., 12],
        avoiding=obs[..., 13] > 0.5,
        neighbour=other[..., 0] > 0.5,
        relative_formation_error=relative,
    )
