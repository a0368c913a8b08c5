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

Backends: :func:`build_observations` (encoding) takes numpy arrays or torch tensors on any device
and answers in the same library (``core/array_api.py``); the decoding side
(:func:`decode_observations`) is numpy only, as the policies that use it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from uav_formation_env.core.array_api import (
    as_float,
    asarray_like,
    constant_like,
    device,
    einsum_in,
    is_numpy,
    namespace_of,
    read_only,
    take,
)
from uav_formation_env.core.cost import anchored

Array = Any  # a numpy array or a torch tensor (core/array_api.py)

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


@lru_cache(maxsize=16)
def others_index(n_uav: int) -> np.ndarray:
    """(N, N-1) index of the k-th other UAV of each UAV (ascending, skipping itself).

    Cached per N and read-only.
    """
    k = np.arange(n_uav - 1)[None, :]
    index = k + (k >= np.arange(n_uav)[:, None])  # k, or k + 1 from UAV i's own column on
    read_only(index)
    return index


@lru_cache(maxsize=16)
def _layout(n_uav: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per-slot constants of the layout for N UAVs, cached and read-only.

    Returns:
        ``(scale, low, high, pairs)``: scale (dim,) is each slot's divisor (1 for the unscaled
        slots); low and high (dim,) are each slot's clip bounds (±DISTANCE_CLIP for the clipped
        distances, else ±OBSERVATION_BOUND); pairs (N, N-1) is the flat index i·N + j of h_ij of
        the k-th other UAV j of UAV i in a row-major (N, N) matrix.
    """
    dim = observation_dim(n_uav)
    scale = np.ones(dim)
    scale[0:9] = VELOCITY_SCALE
    scale[9:12] = ESTIMATE_SCALE
    scale[[14, 15, 16, 18]] = DISTANCE_SCALE
    other = scale[OWN_DIM:].reshape(n_uav - 1, OTHER_DIM)
    other[:, 1:4] = FORMATION_SCALE
    other[:, 4:7] = VELOCITY_SCALE
    high = np.full(dim, OBSERVATION_BOUND)
    high[[14, 15, 16, 18]] = DISTANCE_CLIP
    low = -high
    pairs = np.arange(n_uav)[:, None] * n_uav + others_index(n_uav)
    read_only(scale, low, high, pairs)
    return scale, low, high, pairs


def _as_tensor_like(a: Array, like: Array) -> Array:
    """``a`` (a tensor, or a numpy array such as a read-only broadcast view of the scenario's
    obstacle mask) as a tensor on ``like``'s device, its dtype kept (bool masks stay bool)."""
    if isinstance(a, np.ndarray):
        a = np.array(a)  # writable and contiguous: torch warns on sharing read-only memory
    return namespace_of(like).asarray(a, device=device(like))


@lru_cache(maxsize=16)
def _arange(count: int, step: int) -> np.ndarray:
    """``np.arange(count) * step``, cached and read-only."""
    index = np.arange(count) * step
    read_only(index)
    return index


def build_observations(
    z: Array,
    reference_velocity: Array,
    estimate: Array,
    adjacency: Array,
    avoiding: Array,
    time_fraction: Array,
    offsets: Array,
    obstacle_centers: Array,
    obstacle_radii: Array,
    min_separation: Array,
    obstacle_present: Array | None = None,
) -> Array:
    """Every agent's observation, on the array library of ``z`` (numpy, or torch on any device).

    With torch ``z``, the mission data (``offsets``, the obstacle arrays) may be numpy arrays:
    they are moved to ``z``'s device. Values are computed in ``z``'s dtype (float64 from the sim).

    Args:
        z: (B, N, 6) states [m, m/s].
        reference_velocity: (B, N, 3) v^d [m/s].
        estimate: (B, N, 3) disturbance estimate [m/s^2].
        adjacency: (B, N, N) h_ij, row = receiver.
        avoiding: (B, N) bool.
        time_fraction: (B,) t / duration.
        offsets: (N, 6) formation offsets z^d, or (B, N, 6) per copy.
        obstacle_centers: (O, 2) [m], or (B, O, 2) per copy.
        obstacle_radii: (O,) [m], or (B, O) per copy.
        min_separation: (B, N) nearest other UAV [m].
        obstacle_present: (B, O) bool for per-copy obstacles: padding obstacles are never the
            nearest, and slot 17 says whether the copy has any obstacle.

    Returns:
        (B, N, dim) float32, of ``z``'s library and device.
    """
    # Methods that numpy and torch share (x.reshape(shape), x.ravel(), x.argmin(axis=),
    # x.any(axis=), the flat x.take(index)) rather than the standard's functions: numpy's function
    # forms add a dispatch layer each, a large share of this function at small B.
    xp = namespace_of(z)
    numpy = is_numpy(xp)
    batch, n_uav = z.shape[:2]
    scale, low, high, pairs = _layout(n_uav)
    others = others_index(n_uav)
    if not numpy:  # the cached layout and the mission data (maybe numpy) on z's device
        scale, low, high, pairs, others = (
            constant_like(a, z) for a in (scale, low, high, pairs, others)
        )
        offsets, obstacle_centers, obstacle_radii = (
            asarray_like(a, z) for a in (offsets, obstacle_centers, obstacle_radii)
        )
        if obstacle_present is not None:
            obstacle_present = _as_tensor_like(obstacle_present, z)
    # Raw (unscaled) slots joined into one array, then one division by each slot's scale and one
    # clip to each slot's bounds: x / 1 is exact and clip(±10) then clip(±100) is clip(±10), so
    # every value is the one of scaling and clipping slot by slot, for a fraction of the calls.
    # One concatenation rather than slice writes: torch.compile fuses it into one kernel.
    v = z[..., 3:]
    flags = xp.stack((xp.broadcast_to(time_fraction[:, None], avoiding.shape), avoiding), axis=-1)
    own = [v, v - reference_velocity, reference_velocity, estimate, xp.astype(flags, z.dtype)]
    own.append(_nearest_obstacle(z, obstacle_centers, obstacle_radii, obstacle_present))
    own.append(min_separation[..., None])
    a = anchored(z, offsets)  # (B, N, 6)
    neighbour = take(adjacency.reshape((batch, n_uav * n_uav)), pairs, axis=1)[..., None]
    relative = take(a, others, axis=1) - a[:, :, None]  # (B, N, N-1, 6)
    other = xp.concat((xp.astype(neighbour, z.dtype), relative), axis=-1)
    raw = xp.concat((*own, other.reshape((batch, n_uav, (n_uav - 1) * OTHER_DIM))), axis=-1)
    raw = xp.minimum(xp.maximum(raw / scale, low), high)
    return raw.astype(np.float32) if numpy else xp.astype(raw, xp.float32)


def _nearest_obstacle(z: Array, centers: Array, radii: Array, present: Array | None) -> Array:
    """(B, N, 4) slots 14:18 of each UAV: its nearest obstacle's centre minus its position
    (horizontal) [m], the distance to that obstacle's surface [m], and 1 (zeros where the copy
    has no obstacle). Arguments as :func:`build_observations`'s, on ``z``'s library."""
    xp = namespace_of(z)
    batch, n_uav = z.shape[:2]
    n_obs = radii.shape[-1]
    if not n_obs:
        return xp.zeros((batch, n_uav, 4), dtype=z.dtype, device=device(z))
    per_copy = radii.ndim == 2
    centres = centers[:, None] if per_copy else centers[None, None]
    rel = centres - z[:, :, None, :2]  # (B, N, O, 2)
    centre_dist = xp.sqrt(einsum_in(xp, "bnok,bnok->bno", rel, rel))
    surface = centre_dist - (radii[:, None] if per_copy else radii)
    if present is not None:
        surface = xp.where(present[:, None], surface, xp.inf)
    # flat index of each UAV's nearest obstacle in the (B·N·O,) flattening
    step = _arange(batch * n_uav, n_obs)
    nearest = (step if is_numpy(xp) else constant_like(step, z)) + surface.argmin(axis=-1).ravel()
    centre = take(rel.reshape((-1, 2)), nearest, axis=0).reshape((batch, n_uav, 2))
    distance = surface.take(nearest).reshape((batch, n_uav, 1))  # the flat take
    slots = xp.concat((centre, distance, xp.ones_like(distance)), axis=-1)
    if present is not None:  # a copy without obstacles: zeros
        slots = xp.where(present.any(axis=1)[:, None, None], slots, 0.0)
    return slots


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
    # the nearest obstacle as one slot, the local layout's shape with m = 1
    obstacle_present: np.ndarray  # (..., 1) bool (False beyond the slots' 1000 m clip)
    obstacle_relative: np.ndarray  # (..., 1, 2) centre - own position [m]
    obstacle_radius: np.ndarray  # (..., 1) [m] (distance to the centre minus to the surface)


def require_decodable(scenario, policy: str) -> None:
    """Refuse, naming the option, a scenario whose observations ``policy`` cannot decode.

    The reference DMPC and the heuristic decode the full layout above with the mission data
    (formation offsets) of the scenario, or the N-independent local layout
    (:mod:`uav_formation_env.core.local_observation`), which carries the relative offsets itself.
    A scene that draws the formation or the route per reset needs the local layout.

    Args:
        scenario: a :class:`~uav_formation_env.config.Scenario`.
        policy: the policy's name, for the message.
    """
    scene = scenario.scene
    drawn = scene is not None and (scene.n_uav is not None or scene.shapes is not None)
    if scenario.observation.kind == "full" and drawn:
        raise ValueError(
            f"{policy} reads the formation of the full observation from the scenario, but "
            f"scenario {scenario.name!r} draws it per reset (scene.n_uav / scene.shapes); use "
            "observation.kind='local'"
        )
    if scenario.observation.kind == "full" and scene is not None and scene.route is not None:
        raise ValueError(
            f"{policy} reads the preset route of the full observation from the scenario, but "
            f"scenario {scenario.name!r} draws it per reset (scene.route); use "
            "observation.kind='local' (it holds the next leg)"
        )


def decode_observations(obs: np.ndarray, n_uav: int) -> DecodedObservation:
    """Undo the scaling of :func:`build_observations` (the unclipped slots exactly).

    numpy or torch: the decoded arrays are float64 in the library and on the device of ``obs``
    (the observations themselves are float32)."""
    obs = as_float(obs)
    xp = namespace_of(obs)
    if not is_numpy(xp):
        obs = xp.astype(obs, xp.float64)
    # slots beyond the layout (observation.route_offset) are not the decoders' to read
    other = obs[..., OWN_DIM : observation_dim(n_uav)]
    other = other.reshape(*obs.shape[:-1], n_uav - 1, OTHER_DIM)
    relative = xp.concat(
        (other[..., 1:4] * FORMATION_SCALE, other[..., 4:7] * VELOCITY_SCALE), axis=-1
    )
    centre = obs[..., 14:16] * DISTANCE_SCALE
    surface = obs[..., 16] * DISTANCE_SCALE
    # a clipped slot (an obstacle 1000 m or more away) holds no usable geometry
    present = (obs[..., 17] > 0.5) & (xp.abs(obs[..., 16]) < DISTANCE_CLIP)
    present &= xp.all(xp.abs(obs[..., 14:16]) < DISTANCE_CLIP, axis=-1)
    radius = xp.sqrt(xp.sum(centre**2, axis=-1)) - surface
    return DecodedObservation(
        velocity=obs[..., 0:3] * VELOCITY_SCALE,
        reference_velocity=obs[..., 6:9] * VELOCITY_SCALE,
        estimate=obs[..., 9:12] * ESTIMATE_SCALE,
        time_fraction=obs[..., 12],
        avoiding=obs[..., 13] > 0.5,
        neighbour=other[..., 0] > 0.5,
        relative_formation_error=relative,
        obstacle_present=present[..., None],
        obstacle_relative=centre[..., None, :],
        obstacle_radius=xp.where(present, radius, 0.0)[..., None],
    )
