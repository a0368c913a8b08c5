"""Cylinder geometry for obstacle avoidance (docs/model.md §7), on numpy arrays or torch tensors.

Obstacles are infinite vertical cylinders, so all geometry lives in the horizontal plane: only the
x and y components of positions are used. The track frame of a copy is (ê, n̂): ê is the
horizontal direction of the current preset velocity and n̂ is ê rotated by +90° (counter-clockwise,
seen from above with z up). For UAV i and obstacle o

    λ_lon = (p_i - o)·ê,   λ_lat = (p_i - o)·n̂,   D_i = ||p_i,xy - o||.

A UAV is *in range* of an obstacle when |λ_lat| < R_s and λ_lon < 0 (inside the strip between the
two tangent lines of the safety circle and not yet abreast of the centre).

Shapes: B scenario copies, O obstacles, N UAVs. :func:`relative_geometry` works batch-last,
(O, N, B), for speed; :func:`obstacle_distances` returns (B, N, O) as the public API asks.

Every function takes numpy arrays or torch tensors (core/array_api.py) and returns arrays of the
same library and device; an :class:`ObstacleField` holds arrays of either library
(:func:`obstacle_field` ``like=``, :func:`field_like`), and a configuration's cached numpy arrays
are converted to the inputs' device where torch inputs meet them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from uav_formation_env.config import AvoidanceConfig
from uav_formation_env.core.array_api import (
    as_float,
    constant_like,
    copy,
    device,
    is_numpy,
    namespace_of,
    read_only,
    to_numpy,
)
from uav_formation_env.core.reference import config_cache

__all__ = [
    "ABSENT_CENTRE",
    "ObstacleField",
    "choose_sides",
    "deflection_demand",
    "detection_sq",
    "field_like",
    "heading_frame",
    "in_range",
    "obstacle_arrays",
    "obstacle_distances",
    "obstacle_field",
    "relative_geometry",
    "tangent_direction",
]

_EPS = 1e-9  # lengths / speeds below this count as zero [m], [m/s]
# Centre of a padding obstacle: far from any route, yet finite so its geometry has no NaNs [m]
ABSENT_CENTRE = 1.0e9


@dataclass(frozen=True)
class ObstacleField:
    """The obstacles of each copy, padded to a common count O (scene distributions draw a field
    per reset; a shared field is the same rows in every copy).

    Padding obstacles (``present`` False) sit at :data:`ABSENT_CENTRE` with radius 1 m: they never
    activate, are never the nearest obstacle of a UAV on a route, and are masked in
    observations and metrics.

    The arrays are numpy arrays or torch tensors, all of one library and device.

    Attributes:
        centres: (B, O, 2) horizontal centres [m].
        radii: (B, O) [m].
        r_safe: (B, O) safety radii R_s = radius + safety_margin [m].
        r_detect: (B, O) activation radii of the topology rules: radius + the avoidance's
            ``detection_margin`` (d^o = radius + detection_margin) [m].
        present: (B, O) bool, real obstacles.
    """

    centres: Any
    radii: Any
    r_safe: Any
    r_detect: Any
    present: Any

    @property
    def count(self) -> int:
        """O, obstacles per copy (padding included)."""
        return self.radii.shape[1]

    def set_copy(self, copy: int, avoidance: AvoidanceConfig) -> None:
        """Write copy ``copy``'s rows (in place) from a configuration's obstacles and margins."""
        n = len(avoidance.obstacles)
        if n > self.count:
            raise ValueError(f"{n} obstacles do not fit the padded count {self.count}")
        self.centres[copy] = ABSENT_CENTRE
        self.radii[copy] = 1.0
        self.present[copy] = False
        self.present[copy, :n] = True
        if n:
            xp, at = namespace_of(self.centres), device(self.centres)
            centres = [ob.center for ob in avoidance.obstacles]
            radii = [ob.radius for ob in avoidance.obstacles]
            self.centres[copy, :n] = xp.asarray(centres, dtype=self.centres.dtype, device=at)
            self.radii[copy, :n] = xp.asarray(radii, dtype=self.radii.dtype, device=at)
        self.r_safe[copy] = self.radii[copy] + avoidance.safety_margin
        self.r_detect[copy] = self.radii[copy] + avoidance.detection_margin

    def take(self, mask: Any, source: ObstacleField) -> None:
        """Copy the ``mask`` copies' rows of ``source`` (same library and device) into this field
        (in place). ``mask``: (B,) bool, numpy or of the field's library."""
        if not is_numpy(namespace_of(self.centres)):
            mask = namespace_of(self.centres).asarray(mask, device=device(self.centres))
        for name in _FIELDS:
            getattr(self, name)[mask] = getattr(source, name)[mask]


_FIELDS = ("centres", "radii", "r_safe", "r_detect", "present")


def field_like(field: ObstacleField, like: Any) -> ObstacleField:
    """``field`` with its arrays in the library and on the device of ``like``: to torch, floats in
    :func:`~uav_formation_env.core.array_api.float_dtype` of ``like``; to numpy, float64. The
    field itself when it is numpy already and ``like`` is numpy; arrays already right may be
    shared with ``field``."""
    if is_numpy(namespace_of(like)):
        if isinstance(field.centres, np.ndarray):
            return field
        return ObstacleField(*(np.array(to_numpy(getattr(field, name))) for name in _FIELDS))
    xp = namespace_of(like)
    arrays = {name: as_float(getattr(field, name), like) for name in _FIELDS[:-1]}
    present = np.array(to_numpy(field.present))  # via the host: any library, any device
    present = xp.asarray(present, dtype=xp.bool, device=device(like))
    return ObstacleField(**arrays, present=present)


def obstacle_field(
    avoidances: list[AvoidanceConfig] | tuple[AvoidanceConfig, ...],
    count: int | None = None,
    like: Any = None,
) -> ObstacleField:
    """The :class:`ObstacleField` of one avoidance configuration per copy.

    Args:
        avoidances: B configurations (margins and obstacles of each copy).
        count: O, padded obstacle count (None: the largest count among the copies).
        like: an array whose library and device the field's arrays get (see
            :func:`field_like`); None: numpy.
    """
    if count is None:
        count = max((len(a.obstacles) for a in avoidances), default=0)
    batch = len(avoidances)
    field = ObstacleField(
        centres=np.full((batch, count, 2), ABSENT_CENTRE),
        radii=np.ones((batch, count)),
        r_safe=np.zeros((batch, count)),
        r_detect=np.zeros((batch, count)),
        present=np.zeros((batch, count), dtype=bool),
    )
    for b, avoidance in enumerate(avoidances):
        field.set_copy(b, avoidance)
    return field if like is None else field_like(field, like)


@config_cache
def obstacle_arrays(avoidance: AvoidanceConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Obstacle centres and radii as arrays, cached per (frozen, hashable) configuration.

    Args:
        avoidance: the avoidance configuration.

    Returns:
        centres (O, 2) [m], safety radii R_s = radius + safety_margin (O,) [m] and activation
        radii (d^o = radius + detection_margin) (O,) [m], both
        measured from the centre. The arrays are
        shared between calls and read-only.
    """
    n = len(avoidance.obstacles)
    centres = np.array([ob.center for ob in avoidance.obstacles], dtype=float).reshape(n, 2)
    radii = np.array([ob.radius for ob in avoidance.obstacles], dtype=float).reshape(n)
    arrays = (
        centres,
        radii + avoidance.safety_margin,
        radii + avoidance.detection_margin,
    )
    read_only(*arrays)
    return arrays


@config_cache
def detection_sq(avoidance: AvoidanceConfig) -> np.ndarray:
    """(O,) squared detection radii (d^o)² [m²], cached and read-only."""
    squared = obstacle_arrays(avoidance)[2] ** 2
    read_only(squared)
    return squared


def heading_frame(velocity: Any) -> tuple[Any, Any]:
    """Horizontal track frame (ê, n̂) of a velocity.

    Args:
        velocity: (..., 3) [m/s], normally the preset velocity at the current time (numpy or
            torch).

    Returns:
        e_hat (..., 2) and n_hat (..., 2) = ê rotated +90° [-]. Where the horizontal speed is zero
        both are zero vectors, so that every λ is 0 and no UAV is in range (no avoidance without a
        horizontal direction of travel).
    """
    horizontal = as_float(velocity)[..., :2]
    xp = namespace_of(horizontal)
    # the norm over the last axis of 2: x² + y² is the sum numpy's reduction computes
    x, y = horizontal[..., :1], horizontal[..., 1:]
    speed = xp.sqrt(x * x + y * y)
    e_hat = xp.where(speed > _EPS, horizontal / xp.maximum(speed, _EPS), 0.0)
    n_hat = xp.concat((-e_hat[..., 1:], e_hat[..., :1]), axis=-1)
    return e_hat, n_hat


def relative_geometry(positions: Any, centres: Any, e_hat: Any) -> tuple[Any, Any, Any, Any, Any]:
    """Position of every UAV relative to every obstacle, in the track frame.

    The results are laid out batch-last, (O, N, B), so that reductions over the short UAV and
    obstacle axes run over leading axes (numpy is an order of magnitude slower reducing a short
    trailing axis).

    Args:
        positions: (B, N, 3) or (B, N, 2) [m], numpy or torch.
        centres: (O, 2) obstacle centres shared by every copy, or (B, O, 2) per copy [m] (numpy
            centres are converted to a torch ``positions``' device).
        e_hat: (B, 2) along-track unit vector ê [-]; n̂ = ê rotated +90°.

    Returns:
        rel_x, rel_y (O, N, B) = components of p_xy - o [m], dist D (O, N, B) [m],
        lon λ_lon (O, N, B) [m] and lat λ_lat (O, N, B) [m].
    """
    xp = namespace_of(positions)
    if not is_numpy(xp):
        centres = as_float(centres, like=positions)
    # contiguous (N, B) copies: ufunc results inherit their inputs' memory order
    px = copy(positions[:, :, 0].T)
    py = copy(positions[:, :, 1].T)
    if centres.ndim == 3:  # per copy: (B, O, 2) -> (O, 1, B)
        cx, cy = centres[..., 0].T[:, None, :], centres[..., 1].T[:, None, :]
    else:
        cx, cy = centres[:, 0, None, None], centres[:, 1, None, None]
    rel_x = px[None] - cx
    rel_y = py[None] - cy
    dist = xp.sqrt(rel_x**2 + rel_y**2)
    ex, ey = e_hat[:, 0], e_hat[:, 1]
    lon = rel_x * ex + rel_y * ey
    lat = rel_y * ex - rel_x * ey  # n̂ = (-e_y, e_x)
    return rel_x, rel_y, dist, lon, lat


def in_range(lon: Any, lat: Any, safety_radius: Any) -> Any:
    """The "within the obstacle range" test: |λ_lat| < R_s and λ_lon < 0.

    Args:
        lon: (...) along-track coordinate λ_lon [m].
        lat: (...) lateral coordinate λ_lat [m].
        safety_radius: R_s, broadcastable to ``lon`` [m] (the library of ``lon``).

    Returns:
        (...) bool.
    """
    return (namespace_of(lat).abs(lat) < safety_radius) & (lon < 0.0)


def tangent_direction(
    rel_x: Any,
    rel_y: Any,
    dist: Any,
    safety_radius: Any,
    side: Any,
) -> tuple[Any, Any]:
    """Unit direction l/||l|| of the guide's avoidance reference.

    Outside the safety circle (D > R_s), l is the tangent from the guide to the circle on the
    group's side: u_los = (o - p)/D, α = asin(R_s/D), l = Rot(+s α) u_los. For s = +1 (left of the
    centre line) the tangent is the line of sight turned counter-clockwise, so the group passes
    with the obstacle on its right. Inside (D <= R_s): l = Rot(-s·90°) r̂ + (R_s - D)/R_s r̂ with
    r̂ = (p - o)/D, i.e. the forward tangential direction of the same sense plus an outward push
    that grows with the intrusion; the two rules agree at D = R_s. At D = 0 (exactly on the
    centre) r̂ is undefined and r̂ = +x is used.

    Args:
        rel_x: (...) x of the guide position minus the obstacle centre, p - o [m].
        rel_y: (...) y of p - o [m].
        dist: (...) D = ||p_xy - o|| [m].
        safety_radius: (...) R_s [m].
        side: (...) group side s, +1 or -1 [-] (numpy is converted to a torch ``dist``'s device).
        (All numpy or torch; the safety radius may be a Python or numpy scalar.)

    Returns:
        x and y components (...) of the unit vector [-].
    """
    xp = namespace_of(dist)
    valid = dist > _EPS
    safe_dist = xp.where(valid, dist, 1.0)
    rx = xp.where(valid, rel_x / safe_dist, 1.0)
    ry = xp.where(valid, rel_y / safe_dist, 0.0)
    s = as_float(side, like=dist)
    # outside: Rot(s α)(-r̂), with sin α = R_s/D and cos α = sqrt(1 - sin² α), no trigonometry
    sin_alpha = xp.minimum(safety_radius / safe_dist, 1.0)
    ca = xp.sqrt(1.0 - sin_alpha**2)
    sa = s * sin_alpha
    out_x = sa * ry - ca * rx
    out_y = -sa * rx - ca * ry
    # inside: Rot(-s 90°) r̂ = s (r_y, -r_x), plus the outward radial term
    push = xp.minimum(xp.maximum((safety_radius - dist) / safety_radius, 0.0), 1.0)  # np.clip
    in_x = s * ry + push * rx
    in_y = push * ry - s * rx
    outside = dist > safety_radius
    lx = xp.where(outside, out_x, in_x)
    ly = xp.where(outside, out_y, in_y)
    norm = xp.maximum(xp.sqrt(lx**2 + ly**2), _EPS)
    return lx / norm, ly / norm


def obstacle_distances(positions: Any, avoidance: AvoidanceConfig | ObstacleField) -> Any:
    """Horizontal distance from each UAV to each obstacle centre.

    Args:
        positions: (B, N, 3) [m], numpy or torch (a field's arrays: the same library).
        avoidance: the obstacles of a configuration (shared by every copy), or a per-copy field.

    Returns:
        (B, N, O) [m], in the library of ``positions``.
    """
    if isinstance(avoidance, ObstacleField):
        positions = as_float(positions, like=avoidance.centres)
        centres = avoidance.centres[:, None]  # (B, 1, O, 2)
    else:
        positions = as_float(positions)
        centres = constant_like(obstacle_arrays(avoidance)[0], positions)
    xp = namespace_of(positions)
    rel_sq = xp.square(positions[..., :, None, :2] - centres)
    return xp.sqrt(rel_sq[..., 0] + rel_sq[..., 1])


def choose_sides(lat: Any, deadband: float) -> tuple[Any, Any]:
    """Each UAV's side of an obstacle's centre line at activation, and whether that is case 1.

    docs/model.md §7's rule is the sign of λ_lat. A UAV within ``deadband`` of the centre line has
    no
    meaningful side, so if every UAV of one side is that close the whole formation is assigned
    to the other side (case 1) instead of splitting off a member that sits on the line
    (docs/deviations.md §6). ``deadband = 0`` is the rule of docs/model.md exactly.

    Args:
        lat: (O, N, B) lateral coordinates λ_lat [m], numpy or torch.
        deadband: half-width of the band around the centre line [m].

    Returns:
        ``(side, one_group)``: (O, N, B) int8 sides ±1 and (O, B) bool case 1.
    """
    xp = namespace_of(lat)
    strict = xp.astype(xp.where(lat >= 0.0, 1, -1), xp.int8)
    fits_plus = (lat >= -deadband).all(axis=1)  # (O, B): everyone counts as side +1
    fits_minus = (lat < deadband).all(axis=1)
    one_group = fits_plus | fits_minus
    # If both fit (the whole formation is within the band) the mean position decides.
    whole_side = xp.where(fits_plus & (~fits_minus | (lat.mean(axis=1) >= 0.0)), 1, -1)
    side = xp.where(one_group[:, None], xp.astype(whole_side[:, None], xp.int8), strict)
    return side, one_group  # int8 (where of two int8 arrays), a new array


def deflection_demand(
    rel_x: Any,
    rel_y: Any,
    dist: Any,
    r_safe: Any,
    e_hat: Any,
    slot_sides: Any,
) -> Any:
    """Turn each UAV would need to clear the safety circle on each group side.

    Returns the signed angle from ê to the UAV's own tangent direction, positive towards the side
    of each group slot (``slot_sides``, e.g. (+1, -1)), shape (O, 2, N, B) [rad]. The group's
    guide is the in-range member with the largest value: the one the group must follow for every
    member to clear. ``r_safe`` is (O,) shared or (O, 1, B) per copy [m]. numpy or torch (numpy
    ``slot_sides`` and ``r_safe`` are converted to a torch ``dist``'s device).
    """
    xp = namespace_of(dist)
    sides = as_float(slot_sides, like=dist)[None, :, None, None]
    if not is_numpy(xp):
        r_safe = as_float(r_safe, like=dist)
    r_safe = r_safe[:, None] if r_safe.ndim == 3 else r_safe[:, None, None, None]
    lx, ly = tangent_direction(rel_x[:, None], rel_y[:, None], dist[:, None], r_safe, sides)
    ex, ey = e_hat[:, 0], e_hat[:, 1]
    return xp.atan2(sides * (ex * ly - ey * lx), ex * lx + ey * ly)
