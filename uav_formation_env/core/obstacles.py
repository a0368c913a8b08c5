"""Cylinder geometry for obstacle avoidance (docs/model.md §7), pure numpy.

Obstacles are infinite vertical cylinders, so all geometry lives in the horizontal plane: only the
x and y components of positions are used. The track frame of a copy is (ê, n̂): ê is the
horizontal direction of the current preset velocity and n̂ is ê rotated by +90° (counter-clockwise,
seen from above with z up). For UAV i and obstacle o

    λ_lon = (p_i - o)·ê,   λ_lat = (p_i - o)·n̂,   D_i = ||p_i,xy - o||.

A UAV is *in range* of an obstacle when |λ_lat| < R_s and λ_lon < 0 (inside the strip between the
two tangent lines of the safety circle and not yet abreast of the centre).

Shapes: B scenario copies, O obstacles, N UAVs. :func:`relative_geometry` works batch-last,
(O, N, B), for speed; :func:`obstacle_distances` returns (B, N, O) as the public API asks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uav_formation_env.config import AvoidanceConfig
from uav_formation_env.core.reference import config_cache

__all__ = [
    "ABSENT_CENTRE",
    "ObstacleField",
    "choose_sides",
    "deflection_demand",
    "detection_sq",
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

    Attributes:
        centres: (B, O, 2) horizontal centres [m].
        radii: (B, O) [m].
        r_safe: (B, O) safety radii R_s = radius + safety_margin [m].
        r_detect: (B, O) detection radii d^o = radius + detection_margin [m].
        present: (B, O) bool, real obstacles.
    """

    centres: np.ndarray
    radii: np.ndarray
    r_safe: np.ndarray
    r_detect: np.ndarray
    present: np.ndarray

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
            self.centres[copy, :n] = [ob.center for ob in avoidance.obstacles]
            self.radii[copy, :n] = [ob.radius for ob in avoidance.obstacles]
        self.r_safe[copy] = self.radii[copy] + avoidance.safety_margin
        self.r_detect[copy] = self.radii[copy] + avoidance.detection_margin

    def take(self, mask: np.ndarray, source: ObstacleField) -> None:
        """Copy the ``mask`` copies' rows of ``source`` into this field (in place)."""
        for name in ("centres", "radii", "r_safe", "r_detect", "present"):
            getattr(self, name)[mask] = getattr(source, name)[mask]


def obstacle_field(
    avoidances: list[AvoidanceConfig] | tuple[AvoidanceConfig, ...], count: int | None = None
) -> ObstacleField:
    """The :class:`ObstacleField` of one avoidance configuration per copy.

    Args:
        avoidances: B configurations (margins and obstacles of each copy).
        count: O, padded obstacle count (None: the largest count among the copies).
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
    return field


@config_cache
def obstacle_arrays(avoidance: AvoidanceConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Obstacle centres and radii as arrays, cached per (frozen, hashable) configuration.

    Args:
        avoidance: the avoidance configuration.

    Returns:
        centres (O, 2) [m], safety radii R_s = radius + safety_margin (O,) [m] and detection radii
        d^o = radius + detection_margin (O,) [m], both measured from the centre. The arrays are
        shared between calls and read-only.
    """
    n = len(avoidance.obstacles)
    centres = np.array([ob.center for ob in avoidance.obstacles], dtype=float).reshape(n, 2)
    radii = np.array([ob.radius for ob in avoidance.obstacles], dtype=float).reshape(n)
    arrays = (centres, radii + avoidance.safety_margin, radii + avoidance.detection_margin)
    for array in arrays:
        array.flags.writeable = False
    return arrays


@config_cache
def detection_sq(avoidance: AvoidanceConfig) -> np.ndarray:
    """(O,) squared detection radii (d^o)² [m²], cached and read-only."""
    squared = obstacle_arrays(avoidance)[2] ** 2
    squared.flags.writeable = False
    return squared


def heading_frame(velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal track frame (ê, n̂) of a velocity.

    Args:
        velocity: (..., 3) [m/s], normally the preset velocity at the current time.

    Returns:
        e_hat (..., 2) and n_hat (..., 2) = ê rotated +90° [-]. Where the horizontal speed is zero
        both are zero vectors, so that every λ is 0 and no UAV is in range (no avoidance without a
        horizontal direction of travel).
    """
    horizontal = np.asarray(velocity, dtype=float)[..., :2]
    # np.linalg.norm(axis=-1) of real values, without its Python layer
    speed = np.sqrt(np.add.reduce(horizontal * horizontal, axis=-1, keepdims=True))
    e_hat = np.where(speed > _EPS, horizontal / np.maximum(speed, _EPS), 0.0)
    n_hat = np.empty_like(e_hat)
    np.negative(e_hat[..., 1], out=n_hat[..., 0])
    n_hat[..., 1] = e_hat[..., 0]
    return e_hat, n_hat


def relative_geometry(
    positions: np.ndarray, centres: np.ndarray, e_hat: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Position of every UAV relative to every obstacle, in the track frame.

    The results are laid out batch-last, (O, N, B), so that reductions over the short UAV and
    obstacle axes run over leading axes (numpy is an order of magnitude slower reducing a short
    trailing axis).

    Args:
        positions: (B, N, 3) or (B, N, 2) [m].
        centres: (O, 2) obstacle centres shared by every copy, or (B, O, 2) per copy [m].
        e_hat: (B, 2) along-track unit vector ê [-]; n̂ = ê rotated +90°.

    Returns:
        rel_x, rel_y (O, N, B) = components of p_xy - o [m], dist D (O, N, B) [m],
        lon λ_lon (O, N, B) [m] and lat λ_lat (O, N, B) [m].
    """
    # contiguous (N, B) copies: ufunc results inherit their inputs' memory order
    px = np.ascontiguousarray(positions[:, :, 0].T)
    py = np.ascontiguousarray(positions[:, :, 1].T)
    if centres.ndim == 3:  # per copy: (B, O, 2) -> (O, 1, B)
        cx, cy = centres[..., 0].T[:, None, :], centres[..., 1].T[:, None, :]
    else:
        cx, cy = centres[:, 0, None, None], centres[:, 1, None, None]
    rel_x = px[None] - cx
    rel_y = py[None] - cy
    dist = np.sqrt(rel_x**2 + rel_y**2)
    ex, ey = e_hat[:, 0], e_hat[:, 1]
    lon = rel_x * ex + rel_y * ey
    lat = rel_y * ex - rel_x * ey  # n̂ = (-e_y, e_x)
    return rel_x, rel_y, dist, lon, lat


def in_range(lon: np.ndarray, lat: np.ndarray, safety_radius: np.ndarray) -> np.ndarray:
    """The "within the obstacle range" test: |λ_lat| < R_s and λ_lon < 0.

    Args:
        lon: (...) along-track coordinate λ_lon [m].
        lat: (...) lateral coordinate λ_lat [m].
        safety_radius: R_s, broadcastable to ``lon`` [m].

    Returns:
        (...) bool.
    """
    return (np.abs(lat) < safety_radius) & (lon < 0.0)


def tangent_direction(
    rel_x: np.ndarray,
    rel_y: np.ndarray,
    dist: np.ndarray,
    safety_radius: np.ndarray,
    side: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
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
        side: (...) group side s, +1 or -1 [-].

    Returns:
        x and y components (...) of the unit vector [-].
    """
    valid = dist > _EPS
    safe_dist = np.where(valid, dist, 1.0)
    rx = np.where(valid, rel_x / safe_dist, 1.0)
    ry = np.where(valid, rel_y / safe_dist, 0.0)
    s = np.asarray(side, dtype=float)
    # outside: Rot(s α)(-r̂), with sin α = R_s/D and cos α = sqrt(1 - sin² α), no trigonometry
    sin_alpha = np.minimum(safety_radius / safe_dist, 1.0)
    ca = np.sqrt(1.0 - sin_alpha**2)
    sa = s * sin_alpha
    out_x = sa * ry - ca * rx
    out_y = -sa * rx - ca * ry
    # inside: Rot(-s 90°) r̂ = s (r_y, -r_x), plus the outward radial term
    push = np.minimum(np.maximum((safety_radius - dist) / safety_radius, 0.0), 1.0)  # np.clip
    in_x = s * ry + push * rx
    in_y = push * ry - s * rx
    outside = dist > safety_radius
    lx = np.where(outside, out_x, in_x)
    ly = np.where(outside, out_y, in_y)
    norm = np.maximum(np.sqrt(lx**2 + ly**2), _EPS)
    return lx / norm, ly / norm


def obstacle_distances(
    positions: np.ndarray, avoidance: AvoidanceConfig | ObstacleField
) -> np.ndarray:
    """Horizontal distance from each UAV to each obstacle centre.

    Args:
        positions: (B, N, 3) [m].
        avoidance: the obstacles of a configuration (shared by every copy), or a per-copy field.

    Returns:
        (B, N, O) [m].
    """
    if isinstance(avoidance, ObstacleField):
        centres = avoidance.centres[:, None]  # (B, 1, O, 2)
    else:
        centres = obstacle_arrays(avoidance)[0]
    positions = np.asarray(positions, dtype=float)
    rel_sq = np.square(positions[..., :, None, :2] - centres)
    return np.sqrt(rel_sq[..., 0] + rel_sq[..., 1])


def choose_sides(lat: np.ndarray, deadband: float) -> tuple[np.ndarray, np.ndarray]:
    """Each UAV's side of an obstacle's centre line at activation, and whether that is case 1.

    docs/model.md §7's rule is the sign of λ_lat. A UAV within ``deadband`` of the centre line has
    no
    meaningful side, so if every UAV of one side is that close the whole formation is assigned
    to the other side (case 1) instead of splitting off a member that sits on the line
    (docs/deviations.md §6). ``deadband = 0`` is the rule of docs/model.md exactly.

    Args:
        lat: (O, N, B) lateral coordinates λ_lat [m].
        deadband: half-width of the band around the centre line [m].

    Returns:
        ``(side, one_group)``: (O, N, B) int8 sides ±1 and (O, B) bool case 1.
    """
    strict = np.where(lat >= 0.0, 1, -1).astype(np.int8)
    fits_plus = (lat >= -deadband).all(axis=1)  # (O, B): everyone counts as side +1
    fits_minus = (lat < deadband).all(axis=1)
    one_group = fits_plus | fits_minus
    # If both fit (the whole formation is within the band) the mean position decides.
    whole_side = np.where(fits_plus & (~fits_minus | (lat.mean(axis=1) >= 0.0)), 1, -1)
    side = np.where(one_group[:, None], whole_side[:, None].astype(np.int8), strict)
    return side.astype(np.int8), one_group


def deflection_demand(
    rel_x: np.ndarray,
    rel_y: np.ndarray,
    dist: np.ndarray,
    r_safe: np.ndarray,
    e_hat: np.ndarray,
    slot_sides: np.ndarray,
) -> np.ndarray:
    """Turn each UAV would need to clear the safety circle on each group side.

    Returns the signed angle from ê to the UAV's own tangent direction, positive towards the side
    of each group slot (``slot_sides``, e.g. (+1, -1)), shape (O, 2, N, B) [rad]. The group's
    guide is the in-range member with the largest value: the one the group must follow for every
    member to clear. ``r_safe`` is (O,) shared or (O, 1, B) per copy [m].
    """
    sides = np.asarray(slot_sides)[None, :, None, None].astype(float)
    r_safe = r_safe[:, None] if r_safe.ndim == 3 else r_safe[:, None, None, None]
    lx, ly = tangent_direction(rel_x[:, None], rel_y[:, None], dist[:, None], r_safe, sides)
    ex, ey = e_hat[:, 0], e_hat[:, 1]
    return np.arctan2(sides * (ex * ly - ey * lx), ex * lx + ey * ly)
