"""Scenario configuration: frozen, typed, validated dataclasses.

Every number the simulation uses lives here, with its unit. The defaults are the paper's scenario
(docs/model.md §8 and §9b). A scenario is validated when it is built: impossible values raise
``ValueError`` naming the field and the rule broken. Loading from a dict or YAML file (see
:mod:`uav_formation_env.config_io`) rejects unknown keys by name.

The flags marked *literal* switch on the paper's literal (and, per docs/model.md, inconsistent)
readings;
they are off by default.
"""

from __future__ import annotations

import math
import typing
from dataclasses import dataclass, field, fields, is_dataclass

import numpy as np

Vec3 = tuple[float, float, float]


def _require(condition: bool, field_name: str, rule: str) -> None:
    if not condition:
        raise ValueError(f"invalid scenario field '{field_name}': {rule}")


def _finite(value: float, field_name: str) -> None:
    _require(
        isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool),
        field_name,
        f"must be a number, got {value!r}",
    )
    _require(math.isfinite(value), field_name, f"must be finite, got {value!r}")


def _one_of(value: object, choices: tuple, field_name: str) -> None:
    _require(value in choices, field_name, f"must be one of {choices}, got {value!r}")


def _positive(value: float, field_name: str) -> None:
    _finite(value, field_name)
    _require(value > 0, field_name, f"must be > 0, got {value!r}")


def _non_negative(value: float, field_name: str) -> None:
    _finite(value, field_name)
    _require(value >= 0, field_name, f"must be >= 0, got {value!r}")


def _vec(value: tuple, length: int, field_name: str) -> None:
    _require(len(value) == length, field_name, f"must have {length} components, got {len(value)}")
    for component in value:
        _finite(float(component), field_name)


@dataclass(frozen=True)
class DynamicsConfig:
    """Double-integrator plant (docs/model.md §1)."""

    dt: float = 0.2  # control step δ [s]
    u_max: float = 5.0  # per-axis bound on the applied acceleration [m/s^2]
    mass: float = 10.0  # UAV mass, reporting of thrust/lift only [kg]
    air_density: float = 1.225  # ρ, drag for reporting only [kg/m^3]
    wing_area: float = 0.5  # S, drag for reporting only [m^2]
    drag_coefficient: float = 0.03  # C_D0, drag for reporting only [-]

    def __post_init__(self) -> None:
        _positive(self.dt, "dynamics.dt")
        _positive(self.u_max, "dynamics.u_max")
        _positive(self.mass, "dynamics.mass")
        _non_negative(self.air_density, "dynamics.air_density")
        _non_negative(self.wing_area, "dynamics.wing_area")
        _non_negative(self.drag_coefficient, "dynamics.drag_coefficient")


@dataclass(frozen=True)
class DisturbanceConfig:
    """External disturbance in the acceleration channel (docs/model.md §2).

    The total disturbance is the sum of the eq. 21 part (``model``), a constant ``wind`` and a
    first-order Gauss-Markov gust (``gust_std`` > 0 switches it on).
    """

    model: str = "paper"  # "paper" (eq. 21) or "none"
    amplitude: float = 0.2  # sinusoid amplitude of eq. 21 [m/s^2]
    period: float = 40.0  # sinusoid period of eq. 21, sin(π t / 20) [s]
    noise_scale: float = 0.1  # scale of the U[0, 1) term of eq. 21 [m/s^2]
    scalar_rand: bool = False  # literal: one U[0,1) scalar shared by the three axes
    wind: Vec3 = (0.0, 0.0, 0.0)  # constant wind acceleration [m/s^2]
    gust_std: float = 0.0  # stationary std of the Gauss-Markov gust per axis [m/s^2]; 0 = off
    gust_time_constant: float = 2.0  # gust correlation time τ [s]

    def __post_init__(self) -> None:
        _require(
            self.model in ("paper", "none"),
            "disturbance.model",
            f"must be 'paper' or 'none', got {self.model!r}",
        )
        _non_negative(self.amplitude, "disturbance.amplitude")
        _positive(self.period, "disturbance.period")
        _non_negative(self.noise_scale, "disturbance.noise_scale")
        _vec(self.wind, 3, "disturbance.wind")
        _non_negative(self.gust_std, "disturbance.gust_std")
        _positive(self.gust_time_constant, "disturbance.gust_time_constant")


@dataclass(frozen=True)
class ObserverConfig:
    """NFTSMO gains (docs/model.md §3). Diagonal gains are the same on every axis."""

    enabled: bool = True  # compensate with u_d = -(d_hat + s0)
    substeps: int = 20  # inner observer ticks per control step (h = dt / substeps)
    pi1: float = 1.0  # Π1 [-]
    lambda1: float = 2.0  # λ1 [-], > λ2
    pi2: float = 2.0  # Π2 [-]
    lambda2: float = 1.5  # λ2 [-], in (1, 2) for a non-singular surface
    eta: float = 0.5  # η, switching gain [m/s^3], > sup|d'|
    rho: float = 2.0  # ρ, proportional reaching gain [1/s]
    estimate_without_s0: bool = False  # literal: estimate = d_hat alone (paper_literal_dhat)
    literal_sign_law: bool = False  # literal: d_hat' = (η + ρ) sign(s)

    def __post_init__(self) -> None:
        _require(
            isinstance(self.substeps, int) and self.substeps >= 1,
            "observer.substeps",
            f"must be an integer >= 1, got {self.substeps!r}",
        )
        _positive(self.pi1, "observer.pi1")
        _positive(self.pi2, "observer.pi2")
        _finite(self.lambda2, "observer.lambda2")
        _require(
            1.0 < self.lambda2 < 2.0,
            "observer.lambda2",
            f"must lie in (1, 2) for a non-singular surface, got {self.lambda2!r}",
        )
        _finite(self.lambda1, "observer.lambda1")
        _require(
            self.lambda1 > self.lambda2,
            "observer.lambda1",
            f"must be > lambda2 ({self.lambda2}), got {self.lambda1!r}",
        )
        _positive(self.eta, "observer.eta")
        _non_negative(self.rho, "observer.rho")


PAPER_OFFSETS: tuple[tuple[float, ...], ...] = (
    (0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    (-10.0, 20.0, 0.0, 0.0, 0.0, 0.0),
    (-10.0, -20.0, 0.0, 0.0, 0.0, 0.0),
    (-20.0, 40.0, 0.0, 0.0, 0.0, 0.0),
    (-20.0, -40.0, 0.0, 0.0, 0.0, 0.0),
)
PAPER_ADJACENCY: tuple[tuple[int, ...], ...] = (
    (0, 1, 0, 1, 1),
    (1, 0, 1, 1, 1),
    (1, 1, 0, 1, 1),
    (1, 0, 1, 0, 1),
    (1, 1, 1, 0, 0),
)


def _reached(root: int, targets: np.ndarray, starts: np.ndarray, seen: np.ndarray) -> None:
    """Mark in ``seen`` every node reachable from ``root`` (breadth first, one numpy call per
    level) over edges in CSR form: the out-neighbours of u are ``targets[starts[u]:starts[u+1]]``.
    """
    frontier = np.array([root])
    seen[root] = True
    while frontier.size:
        counts = starts[frontier + 1] - starts[frontier]
        total = int(counts.sum())
        if total == 0:
            break
        first = np.repeat(starts[frontier] - np.cumsum(counts) + counts, counts)
        nodes = np.unique(targets[first + np.arange(total)])
        frontier = nodes[~seen[nodes]]
        seen[frontier] = True


def has_directed_spanning_tree(adjacency: np.ndarray) -> bool:
    """Whether the graph with ``adjacency[i, j] = 1`` (i receives from j) has a spanning tree.

    Edges point j -> i. A spanning tree exists iff some root reaches every node. Linear in the
    number of edges: searches are started from every node not yet reached; the last such start
    is the only candidate root (any root reaches every later start), then one search from it
    decides.

    Args:
        adjacency: (N, N) 0/1 matrix.
    """
    adjacency = np.asarray(adjacency)
    n = adjacency.shape[0]
    receivers, senders = np.nonzero(adjacency)  # row-major: sorted by receiver
    order = np.argsort(senders, kind="stable")
    targets = receivers[order]
    starts = np.searchsorted(senders[order], np.arange(n + 1))
    seen = np.zeros(n, dtype=bool)
    candidate = 0
    for node in range(n):
        if not seen[node]:
            _reached(node, targets, starts, seen)
            candidate = node
    seen[:] = False
    _reached(candidate, targets, starts, seen)
    return bool(seen.all())


def _zero_one_matrix(rows: tuple[tuple[float, ...], ...]) -> np.ndarray:
    """(N, N) array of a square matrix given as rows; integers 0..255 through bytes (a swarm's
    graph of 10^6 entries converts ~4x faster than by np.asarray), anything else as floats."""
    try:
        flat = np.frombuffer(b"".join(map(bytes, rows)), dtype=np.uint8)
    except (TypeError, ValueError):  # floats, negative or large numbers: the general path
        return np.asarray(rows, dtype=float)
    return flat.reshape(len(rows), len(rows))


@dataclass(frozen=True)
class FormationConfig:
    """Formation shape z^d and communication graph H0 (eq. 22)."""

    # z^d per UAV: [x, y, z, vx, vy, vz] offsets [m, m, m, m/s, m/s, m/s]
    offsets: tuple[tuple[float, ...], ...] = PAPER_OFFSETS
    # h_ij = 1: UAV i receives from UAV j (row = receiver); zero diagonal
    adjacency: tuple[tuple[int, ...], ...] = PAPER_ADJACENCY
    mirrored_offsets: bool = False  # literal: z_ij^d = z^d_j - z^d_i (mirrored shape)

    def __post_init__(self) -> None:
        n = len(self.offsets)
        _require(n >= 2, "formation.offsets", f"needs at least 2 UAVs, got {n}")
        for row in self.offsets:
            _vec(tuple(row), 6, "formation.offsets")
        adjacency = self.adjacency
        _require(
            len(adjacency) > 0 and all(len(row) == len(adjacency) for row in adjacency),
            "formation.adjacency",
            "must be a square matrix (N rows of N entries)",
        )
        _require(
            len(adjacency) == n,
            "formation.adjacency",
            f"is {len(adjacency)}x{len(adjacency)} but formation.offsets has {n} UAVs",
        )
        matrix = _zero_one_matrix(adjacency)
        _require(
            bool(np.isin(matrix, (0.0, 1.0)).all()),
            "formation.adjacency",
            "entries must be 0 or 1",
        )
        _require(bool((np.diag(matrix) == 0).all()), "formation.adjacency", "diagonal must be 0")
        _require(
            has_directed_spanning_tree(matrix),
            "formation.adjacency",
            "graph has no directed spanning tree (some UAVs can never be reached)",
        )

    @property
    def n_uav(self) -> int:
        return len(self.offsets)

    @property
    def slot_offsets(self) -> np.ndarray:
        """(N, 6) the offsets z^d as the core reads them, ``a = z - z^d``: ``offsets``, negated
        for the literal mirrored reading (``z_ij^d = z^d_j - z^d_i``), so that the core never
        sees the flag."""
        offsets = np.asarray(self.offsets, dtype=float)
        return -offsets if self.mirrored_offsets else offsets


@dataclass(frozen=True)
class ObstacleConfig:
    """An infinite vertical cylinder."""

    center: tuple[float, float]  # horizontal centre (x, y) [m]
    radius: float = 30.0  # [m]

    def __post_init__(self) -> None:
        _vec(self.center, 2, "avoidance.obstacles.center")
        _positive(self.radius, "avoidance.obstacles.radius")


PAPER_OBSTACLES = (ObstacleConfig((300.0, 0.0)), ObstacleConfig((1050.0, 400.0)))


@dataclass(frozen=True)
class AvoidanceConfig:
    """Obstacles and the topology-reconstruction rules (docs/model.md §7)."""

    obstacles: tuple[ObstacleConfig, ...] = PAPER_OBSTACLES
    safety_margin: float = 10.0  # R_s = radius + margin [m]
    detection_margin: float = 40.0  # d^o = radius + margin, from the centre [m]
    reference_speed: str = "preset"  # "preset": |v^d| of the schedule; "current": |v_guide|
    min_reference_speed: float = 15.0  # floor of the "current" option [m/s]
    # UAVs this close to an obstacle's centre line join the other side's group if that avoids a
    # split (docs/deviations.md §6); 0 is the sign rule of docs/model.md [m]
    split_deadband: float = 5.0
    # several obstacles may be active at once (docs/deviations.md §3): then only the safety
    # circles must not overlap, and detection circles may; False: one at a time, as the paper
    concurrent: bool = False
    # a done obstacle activates again when a UAV comes back into its range (a turn of the route
    # can lead the formation back to it); False: each obstacle once per episode, as the paper
    rearm: bool = False
    # route return: outside an avoidance the reference is the preset velocity plus
    # route_gain x (preset route point - formation centroid), horizontal, at most
    # route_correction_max; 0 is the paper (the preset velocity alone) [1/s], [m/s]
    route_gain: float = 0.0
    route_correction_max: float = 5.0
    # the graph inside a sub-formation while an obstacle is active: "complete" (the paper) or
    # "base" (H0's own edges inside it: a swarm's in-degree stays small, docs/scenarios.md)
    split_graph: str = "complete"
    # turn preview: within this long before a turn of the route, an obstacle is also judged
    # along the next leg from where each UAV will be at the turn (its position plus the preset
    # velocity until the switch), so an obstacle just past a turn activates before the turn, and
    # within it sides come from each UAV's chord to the next leg (a corner obstacle is passed on
    # the inside of the bend); 0 is the paper (the current leg only) [s]
    turn_preview: float = 0.0
    # corner blend: outside an avoidance the reference is the preset velocity averaged over a
    # window this long centred on now, so that a turn of the route ramps over the window instead
    # of switching at once (core/reference.py: blended_velocity); the route point is the same
    # once the window has passed; 0 is the paper (the preset velocity of eq. 23) [s]
    turn_blend: float = 0.0
    # pace keeping: an avoiding group's tangent speed is |v^d| / cos(angle of the tangent to the
    # preset direction), at most pace_limit x |v^d|, so it keeps the route point's pace along the
    # route while it goes round; 1 is the paper (|v^d| along the tangent) [-]
    pace_limit: float = 1.0

    def __post_init__(self) -> None:
        _non_negative(self.route_gain, "avoidance.route_gain")
        _non_negative(self.turn_preview, "avoidance.turn_preview")
        _non_negative(self.turn_blend, "avoidance.turn_blend")
        _require(
            self.pace_limit >= 1.0, "avoidance.pace_limit", f"must be >= 1, got {self.pace_limit!r}"
        )
        _non_negative(self.route_correction_max, "avoidance.route_correction_max")
        _require(
            self.split_graph in ("complete", "base"),
            "avoidance.split_graph",
            f"must be 'complete' or 'base', got {self.split_graph!r}",
        )
        for name in ("concurrent", "rearm"):
            _require(
                isinstance(getattr(self, name), bool),
                f"avoidance.{name}",
                f"must be true or false, got {getattr(self, name)!r}",
            )
        _positive(self.safety_margin, "avoidance.safety_margin")
        _non_negative(self.split_deadband, "avoidance.split_deadband")
        _positive(self.detection_margin, "avoidance.detection_margin")
        _require(
            self.detection_margin > self.safety_margin,
            "avoidance.detection_margin",
            f"must exceed safety_margin ({self.safety_margin}), got {self.detection_margin}",
        )
        _require(
            self.reference_speed in ("preset", "current"),
            "avoidance.reference_speed",
            f"must be 'preset' or 'current', got {self.reference_speed!r}",
        )
        _non_negative(self.min_reference_speed, "avoidance.min_reference_speed")
        for a in range(len(self.obstacles)):
            for b in range(a + 1, len(self.obstacles)):
                oa, ob = self.obstacles[a], self.obstacles[b]
                gap = math.dist(oa.center, ob.center)
                reach = self.min_centre_distance(oa.radius, ob.radius)
                circles = "safety" if self.concurrent else "detection"
                _require(
                    gap >= reach,
                    "avoidance.obstacles",
                    f"obstacles {a} and {b} overlap: their {circles} circles need centres "
                    f">= {reach:.1f} m apart, got {gap:.1f} m",
                )

    def min_centre_distance(self, radius_a: float, radius_b: float) -> float:
        """Smallest distance between two obstacles' centres [m]: their detection circles may
        not overlap, or, when ``concurrent``, their safety circles."""
        margin = self.safety_margin if self.concurrent else self.detection_margin
        return radius_a + radius_b + 2 * margin

    def safety_radius(self, obstacle: ObstacleConfig) -> float:
        """R_s of one obstacle [m]."""
        return obstacle.radius + self.safety_margin


MAX_HORIZON = 1000  # longest MPC horizon [steps]: the populations grow as P x H x 3 per UAV


@dataclass(frozen=True)
class CostConfig:
    """Weights and horizon of the game cost J_i (eq. 6, docs/model.md §4).

    ``separation`` and ``separation_distance`` add a term the paper does not have (see
    docs/deviations.md): ``s Σ_{j≠i} max(0, d_s - ||p_i - p_j||)²`` over every other UAV (sensed,
    not only neighbours), at k = 0..H. It is zero whenever all UAVs are at least d_s apart, e.g. in
    the paper's formation (spacing >= 22.4 m). ``separation = 0`` gives the paper's J_i.

    ``obstacle``, ``obstacle_margin`` and ``obstacle_lookahead`` add another (docs/deviations.md
    §8): ``o Σ_k max(0, R_o + c_o - D_i(k))²`` over the obstacles, with D_i the horizontal
    distance of UAV i from an obstacle's centre, R_o its radius and c_o the margin, at k = 0..H
    and, in the MPC's horizon, also at ``obstacle_lookahead`` points of the free continuation
    (zero inputs) of the terminal state, δ apart: a UAV heading into an obstacle pays for it
    before its 1 s horizon reaches the obstacle. It is zero outside every obstacle's clearance
    circle. ``obstacle = 0`` (the default, and the paper's J_i) switches it off.
    """

    q: float = 1.0  # formation error weight, k = 0..H-1 [1/m^2]
    r: float = 5.0  # control energy weight [s^4/m^2]
    m: float = 1.0  # terminal formation error weight [1/m^2]
    n: float = 10.0  # preset-velocity weight, k = 0..H [s^2/m^2]
    horizon: int = 5  # prediction horizon N (inputs u(0..N-1), terminal state at N) [steps]
    separation: float = 30.0  # s, weight of the separation penalty [1/m^2]
    separation_distance: float = 10.0  # d_s, pairs closer are penalised [m]
    obstacle: float = 0.0  # o, weight of the obstacle clearance penalty [1/m^2]
    obstacle_margin: float = 10.0  # c_o, clearance kept from an obstacle's surface [m]
    # free-flight points after the horizon at which the MPC also evaluates the term [steps]
    obstacle_lookahead: int = 0

    def __post_init__(self) -> None:
        for name in (
            "q", "r", "m", "n", "separation", "separation_distance", "obstacle", "obstacle_margin"
        ):  # fmt: skip
            _non_negative(getattr(self, name), f"cost.{name}")
        _require(
            isinstance(self.horizon, int)
            and not isinstance(self.horizon, bool)
            and 1 <= self.horizon <= MAX_HORIZON,
            "cost.horizon",
            f"must be an integer in [1, {MAX_HORIZON}], got {self.horizon!r}",
        )
        _require(
            isinstance(self.obstacle_lookahead, int)
            and not isinstance(self.obstacle_lookahead, bool)
            and self.obstacle_lookahead >= 0,
            "cost.obstacle_lookahead",
            f"must be an integer >= 0 (control steps), got {self.obstacle_lookahead!r}",
        )


@dataclass(frozen=True)
class ScheduleConfig:
    """Preset desired velocity (eq. 23): velocities[k] holds for times[k-1] < t <= times[k]."""

    times: tuple[float, ...] = (50.0, 100.0, 150.0)  # switching times [s]
    velocities: tuple[Vec3, ...] = (
        (20.0, 0.0, 0.0),
        (0.0, 20.0, 0.0),
        (-20.0, 0.0, 0.0),
        (0.0, -20.0, 0.0),
    )  # [m/s]

    def __post_init__(self) -> None:
        _require(
            len(self.velocities) == len(self.times) + 1,
            "schedule.velocities",
            f"needs len(times) + 1 = {len(self.times) + 1} entries, got {len(self.velocities)}",
        )
        for v in self.velocities:
            _vec(tuple(v), 3, "schedule.velocities")
        for t in self.times:
            _finite(t, "schedule.times")
        _require(
            all(a < b for a, b in zip(self.times, self.times[1:])),
            "schedule.times",
            "must be strictly increasing",
        )


# fraction of the volume bound (InitialStateConfig.capacity) that the start sampler fills
# reliably in a box of 0..3 dimensions, a little under the fill it reached before failing
# (1-d 0.68, 2-d 0.40-0.42, 3-d 0.22; docs/deviations.md)
SAMPLER_FILL = (1.0, 0.62, 0.39, 0.2)


@dataclass(frozen=True)
class InitialStateConfig:
    """Initial-state distribution: positions uniform in a box, one common velocity (docs/model.md
    §8).

    Positions are drawn uniformly in the box and redrawn (only the UAVs too close to another)
    until every pair is at least ``min_spacing`` apart, so no episode starts in a collision. A
    first draw that already keeps the spacing is used as it is.
    """

    position_low: Vec3 = (0.0, -40.0, 0.0)  # [m]
    position_high: Vec3 = (40.0, 40.0, 0.0)  # [m]
    velocity: Vec3 = (20.0, 0.0, 0.0)  # [m/s]
    # minimum distance between two UAVs at t = 0, 2.5x the default collision distance [m]
    min_spacing: float = 5.0
    # None: uniform in the box (the paper's); a value: a start in formation, each UAV at its slot
    # about the box's centre, moved by U(-jitter, jitter) on each horizontal axis [m]
    formation_jitter: float | None = None

    def __post_init__(self) -> None:
        if self.formation_jitter is not None:
            _non_negative(self.formation_jitter, "initial.formation_jitter")
        _vec(self.position_low, 3, "initial.position_low")
        _vec(self.position_high, 3, "initial.position_high")
        _vec(self.velocity, 3, "initial.velocity")
        _require(
            all(lo <= hi for lo, hi in zip(self.position_low, self.position_high)),
            "initial.position_high",
            "must be >= position_low on every axis",
        )
        _non_negative(self.min_spacing, "initial.min_spacing")

    def capacity(self) -> float:
        """An upper bound on how many UAVs fit in the box at ``min_spacing`` (inf if 0).

        Discs (balls) of radius s/2 around points s apart do not overlap and lie in the box
        grown by s/2 on every side; in the d axes where the box has extent, their number is at
        most that grown volume over one ball's volume.
        """
        s = self.min_spacing
        if s == 0:
            return math.inf
        extents = [hi - lo for lo, hi in zip(self.position_low, self.position_high) if hi > lo]
        d = len(extents)
        ball = math.pi ** (d / 2) / math.gamma(d / 2 + 1) * (s / 2) ** d
        return math.prod(e + s for e in extents) / ball

    def sampler_capacity(self) -> int:
        """How many UAVs the start sampler (``core.initial.initial_positions``: redraws of the
        close ones) places reliably: :meth:`capacity` times the fill it reaches in the box's
        dimension (:data:`SAMPLER_FILL`, measured; docs/deviations.md)."""
        bound = self.capacity()
        if math.isinf(bound):
            return 2**62
        d = sum(hi > lo for lo, hi in zip(self.position_low, self.position_high))
        return int(bound * SAMPLER_FILL[d])


@dataclass(frozen=True)
class MissionConfig:
    """What completing the mission means (:mod:`uav_formation_env.evaluation.mission`).

    An episode completes the mission when every obstacle that the preset route passes within
    the detection distance d^o of is met, no UAVs collide after t = 0, and the formation
    centroid never strays more than ``max_route_error`` from the preset route.
    """

    # largest horizontal distance of the centroid from the preset route that still completes [m]
    max_route_error: float = 100.0

    def __post_init__(self) -> None:
        _positive(self.max_route_error, "mission.max_route_error")


@dataclass(frozen=True)
class CollisionConfig:
    """What counts as a collision and what it does (the env reports it either way)."""

    uav_distance: float = 2.0  # two UAVs closer than this collide [m]
    obstacle_distance: float = 0.0  # a UAV closer than this to an obstacle's surface collides [m]
    mode: str = "none"  # "none" (report only), "penalty" (reward -= penalty), "terminate"
    penalty: float = 1000.0  # cost added on a collision step in "penalty" mode [-]

    def __post_init__(self) -> None:
        _non_negative(self.uav_distance, "collision.uav_distance")
        _non_negative(self.obstacle_distance, "collision.obstacle_distance")
        _require(
            self.mode in ("none", "penalty", "terminate"),
            "collision.mode",
            f"must be 'none', 'penalty' or 'terminate', got {self.mode!r}",
        )
        _non_negative(self.penalty, "collision.penalty")


OBSERVATION_KINDS = ("full", "local")


@dataclass(frozen=True)
class ObservationConfig:
    """What each agent's observation vector holds (docs/model.md §5 and
    :mod:`uav_formation_env.core.local_observation`).

    - ``"full"``: the paper-era layout of :mod:`uav_formation_env.core.observation`, a slot block
      per other UAV (19 + 7 (N - 1) values): exactly what the reference DMPC decodes, and what
      Table 2 is reproduced with.
    - ``"local"``: independent of N (19 + 11 (k + r) + 5 m values): the agent's own features,
      its ``neighbours`` nearest graph neighbours (then the nearest other sensed UAVs), its
      ``nearest`` closest other UAVs not already in a slot (proximity slots, r) and its
      ``obstacles`` nearest obstacles, each slot with a presence mask, so that one shared policy
      flies any N and any field. k = 4 is the paper graph's largest in-degree (at N = 5 every
      other UAV has a slot) and the k of the k-nearest swarm graphs; r = 2 keeps the nearest
      non-neighbours in view, whom the separation term must see (with r = 0, LFPIO had UAV-UAV
      collisions on 5 of 6 ``random_swarm`` seeds); m = 2 holds the obstacle being avoided and
      the next one.
    """

    kind: str = "full"  # "full" or "local"
    neighbours: int = 4  # k, neighbour slots of the local layout [-]
    obstacles: int = 2  # m, obstacle slots of the local layout [-]
    nearest: int = 2  # r, proximity slots of the local layout [-]
    # other UAVs are sensed within this distance (core.proximity: pair terms linear in N); None:
    # every other UAV of the copy (all pairs). Must be >= cost.separation_distance and
    # collision.uav_distance, so that J_i and collisions are the same either way [m]
    sensing_radius: float | None = None
    # append UAV i's offset from its slot on the preset route, horizontal (x, y) / 100 m, clipped
    # ±10: the mission's route error, which J_i does not hold (2 slots at the end)
    route_offset: bool = False

    def __post_init__(self) -> None:
        _require(
            isinstance(self.route_offset, bool),
            "observation.route_offset",
            f"must be true or false, got {self.route_offset!r}",
        )
        if self.sensing_radius is not None:
            _positive(self.sensing_radius, "observation.sensing_radius")
        _one_of(self.kind, OBSERVATION_KINDS, "observation.kind")
        for name in ("neighbours", "obstacles", "nearest"):
            value = getattr(self, name)
            least = 0 if name == "nearest" else 1
            _require(
                isinstance(value, int) and not isinstance(value, bool) and value >= least,
                f"observation.{name}",
                f"must be an integer >= {least}, got {value!r}",
            )


REWARD_TRANSFORMS = ("raw", "scaled", "log1p", "train")
ACTION_MODES = ("acceleration", "velocity")
START_MODES = ("zero", "random", "staggered")
START_CONTROLLERS = ("heuristic",)


@dataclass(frozen=True)
class TrainingRewardConfig:
    """The named training reward ``episode.reward = "train"`` (docs/training.md has the table).

    Per UAV and step, a weighted sum of kernels K(e², σ) = 1 / (1 + e² / σ²) in (0, 1], so that
    the reward is O(1), positive, and ending an episode early stops paying:

    - J_i's terms, each normalised by its weight and a scale: ``velocity`` K(|v_i - v^d_i|², σ_v),
      ``formation`` K(|ε_ij|² averaged over the UAVs j that i hears, σ_f), ``energy``
      K(|u_i|², σ_u), ``separation`` K(Σ_j max(0, d_s - d_ij)², σ_s);
    - the mission's terms: ``route`` K(e_i², σ_r) with e_i UAV i's horizontal offset from its
      slot on the preset route, ``clearance`` K(max(0, c - D_i)², σ_c) with D_i the distance to
      the nearest obstacle surface;
    - ``termination_penalty`` subtracted from every agent in a step that terminates its copy (a
      collision in ``"terminate"`` mode, or leaving the corridor).
    """

    velocity: float = 0.15  # weight of the velocity kernel [-]
    formation: float = 0.35  # weight of the formation kernel [-]
    route: float = 0.25  # weight of the route kernel [-]
    energy: float = 0.05  # weight of the energy kernel [-]
    separation: float = 0.1  # weight of the separation kernel [-]
    clearance: float = 0.1  # weight of the obstacle clearance kernel [-]
    velocity_scale: float = 5.0  # σ_v [m/s]
    formation_scale: float = 20.0  # σ_f [m]
    route_scale: float = 30.0  # σ_r [m]
    energy_scale: float = 2.0  # σ_u [m/s^2]
    separation_scale: float = 5.0  # σ_s [m]
    clearance_margin: float = 10.0  # c, clearance wanted from an obstacle's surface [m]
    clearance_scale: float = 5.0  # σ_c [m]
    termination_penalty: float = 10.0  # subtracted in a terminating step [-]

    def __post_init__(self) -> None:
        for name in ("velocity", "formation", "route", "energy", "separation", "clearance"):
            _non_negative(getattr(self, name), f"episode.train.{name}")
        for name in (
            "velocity_scale",
            "formation_scale",
            "route_scale",
            "energy_scale",
            "separation_scale",
            "clearance_scale",
        ):
            _positive(getattr(self, name), f"episode.train.{name}")
        _non_negative(self.clearance_margin, "episode.train.clearance_margin")
        _non_negative(self.termination_penalty, "episode.train.termination_penalty")


@dataclass(frozen=True)
class EpisodeConfig:
    """What a step means to a learner beyond the physics: the training devices of the episode
    layer (:mod:`uav_formation_env.episode`). Every device is off by default, so the reward is
    minus the stage J_i (minus the collision penalty) and episodes end only by
    ``collision.mode`` and the duration.

    - ``reward``: ``"raw"`` ``-(J_i + penalty)``; ``"scaled"`` the same divided by
      ``reward_scale``; ``"log1p"`` ``-log(1 + (J_i + penalty) / reward_scale)``, which keeps the
      eight decades J_i spans within a few units. The raw J_i is always in the infos.
    - Divergence: a copy in which some UAV is more than ``max_formation_error`` from its slot of
      the formation (anchored at the swarm's mean) or more than ``max_velocity_error`` from its
      reference velocity is *truncated* (neither rewarded nor punished for diverging); 0 = off.
    - Mission corridor: a copy whose formation centroid is more than ``corridor_width`` from the
      preset route (horizontally) is *terminated*, as a failed mission; 0 = off. Since every
      reward is negative, ending early also stops the costs: ``corridor_penalty`` is added to
      each agent's cost in the step that leaves the corridor, so that leaving costs more than
      the episode's remaining costs would (e.g. remaining steps x a typical stage cost).
    - Start along the mission: ``start="zero"`` starts every episode at t = 0; ``"random"``
      starts each episode at a step drawn uniformly in [0, T) from the copy's generator,
      ``"staggered"`` spreads the copies of the first reset evenly over [0, T) (copy b at step
      b T / B; later resets start at 0). The state there is the one the ``start_controller``
      (the consensus PD ``"heuristic"``) reaches by flying the episode from t = 0, so that short
      rollouts see both obstacles and every turn.
    - ``max_cycles``: truncate an episode after this many steps from its start (PettingZoo's
      ``max_cycles``); 0 = off, episodes end at ``Scenario.duration``.
    """

    reward: str = "raw"  # "raw", "scaled" or "log1p"
    reward_scale: float = 1.0  # J_0 of "scaled" and "log1p" [-]
    max_formation_error: float = 0.0  # divergence bound on a UAV's formation error [m]; 0 = off
    max_velocity_error: float = 0.0  # divergence bound on |v_i - v^d_i| [m/s]; 0 = off
    corridor_width: float = 0.0  # half-width of the corridor around the preset route [m]; 0 = off
    corridor_penalty: float = 0.0  # cost added to each agent on leaving the corridor [-]
    start: str = "zero"  # "zero", "random" or "staggered": where along the mission episodes start
    start_controller: str = "heuristic"  # flies a copy to its start step
    train: TrainingRewardConfig = field(default_factory=TrainingRewardConfig)  # reward "train"
    # "acceleration": a · u_max; "velocity": a set-point v^d_i + a · velocity_range tracked by
    # u = clip(velocity_gain (set-point - v_i), ±u_max) (core.dynamics.velocity_setpoint_input)
    action: str = "acceleration"
    velocity_range: float = 10.0  # set-point offset at |a| = 1 [m/s]
    velocity_gain: float = 1.0  # inner-loop gain of the velocity mode [1/s]
    max_cycles: int = 0  # truncate after this many steps of an episode; 0 = off [steps]

    def __post_init__(self) -> None:
        _one_of(self.action, ACTION_MODES, "episode.action")
        _positive(self.velocity_range, "episode.velocity_range")
        _positive(self.velocity_gain, "episode.velocity_gain")
        _one_of(self.reward, REWARD_TRANSFORMS, "episode.reward")
        _positive(self.reward_scale, "episode.reward_scale")
        _non_negative(self.max_formation_error, "episode.max_formation_error")
        _non_negative(self.max_velocity_error, "episode.max_velocity_error")
        _non_negative(self.corridor_width, "episode.corridor_width")
        _non_negative(self.corridor_penalty, "episode.corridor_penalty")
        _one_of(self.start, START_MODES, "episode.start")
        _one_of(self.start_controller, START_CONTROLLERS, "episode.start_controller")
        _require(
            isinstance(self.max_cycles, int)
            and not isinstance(self.max_cycles, bool)
            and self.max_cycles >= 0,
            "episode.max_cycles",
            f"must be an integer >= 0 (0 = off), got {self.max_cycles!r}",
        )


# The training task's scenario overrides (uav_formation_env.tasks, docs/training.md): the bounded
# reward, the velocity action mode, the first reset spread over the mission (every rollout holds
# every phase of it), a 150 m mission corridor (the mission allows 100 m), collisions that end
# the episode, and the route offset in the observation.
TRAINING_PRESET: dict[str, object] = {
    "episode__reward": "train",
    "episode__action": "velocity",
    "episode__start": "staggered",
    "episode__corridor_width": 150.0,
    "collision__mode": "terminate",
    "observation__route_offset": True,
}
REWARD_CHOICES = (None, "paper", "train")  # the ``reward`` argument of every view


# the names of formations.SHAPES: config imports no other module of the package (the lowest
# layer), so the list is repeated here; tests/test_scenes.py keeps the two equal
FORMATION_SHAPES = ("v", "line_abreast", "column", "wedge", "grid", "circle")


def _as_tuple(owner: object, name: str, field_name: str) -> tuple:
    """The field ``name`` of a frozen dataclass as a tuple (lists accepted, so that the config
    stays hashable), or a ValueError naming it."""
    value = getattr(owner, name)
    _require(
        isinstance(value, tuple | list),
        field_name,
        f"must be a sequence, got {value!r}",
    )
    value = tuple(value)
    object.__setattr__(owner, name, value)
    return value


def _range(owner: object, name: str, field_name: str, kind: type = float) -> tuple:
    """Validate an inclusive range ``(low, high)``: two finite numbers (integers when ``kind`` is
    int), low <= high. Returns it as a tuple."""
    value = _as_tuple(owner, name, field_name)
    _require(len(value) == 2, field_name, f"must be a (low, high) pair, got {value!r}")
    for bound in value:
        if kind is int:
            _require(
                isinstance(bound, int | np.integer) and not isinstance(bound, bool),
                field_name,
                f"bounds must be integers, got {value!r}",
            )
        else:
            _require(
                isinstance(bound, int | float | np.number) and not isinstance(bound, bool),
                field_name,
                f"bounds must be numbers, got {value!r}",
            )
            _finite(float(bound), field_name)
    _require(value[0] <= value[1], field_name, f"needs low <= high, got {value!r}")
    return value


@dataclass(frozen=True)
class ObstacleFieldConfig:
    """A random obstacle field, drawn along the preset route (:func:`uav_formation_env.scenes.
    draw_scene`).

    Each obstacle's centre is the route point at arc length ``along`` x (route length), moved
    ``across`` metres perpendicular to that leg (positive: to the left of the direction of
    flight). Placements whose detection circles (radius + ``avoidance.detection_margin``) come
    closer than ``min_gap`` to another's, or whose centre lies within ``clear_start`` of the
    route start, are redrawn: every drawn field satisfies :class:`AvoidanceConfig`'s rule.
    """

    count: tuple[int, int] = (1, 4)  # number of obstacles, inclusive range [-]
    radius: tuple[float, float] = (15.0, 35.0)  # obstacle radius [m]
    along: tuple[float, float] = (0.1, 0.9)  # centre along the route, fraction of its length [-]
    across: tuple[float, float] = (-40.0, 40.0)  # lateral offset of the centre from the route [m]
    min_gap: float = 0.0  # extra clearance between two obstacles' detection circles [m]
    # probability that an obstacle is centred near a turn of the route (arc length within its
    # detection distance of the turn), so that avoidance and turning overlap; an obstacle that
    # finds no room near a turn goes anywhere along the route [-]
    near_turns: float = 0.0
    clear_start: float = 150.0  # no obstacle centre within this distance of the route start [m]

    def __post_init__(self) -> None:
        count = _range(self, "count", "scene.obstacles.count", int)
        _require(count[0] >= 0, "scene.obstacles.count", f"must be >= 0, got {count!r}")
        radius = _range(self, "radius", "scene.obstacles.radius")
        _require(radius[0] > 0, "scene.obstacles.radius", f"must be > 0, got {radius!r}")
        along = _range(self, "along", "scene.obstacles.along")
        _require(
            along[0] >= 0.0 and along[1] <= 1.0,
            "scene.obstacles.along",
            f"must lie in [0, 1] (fractions of the route length), got {along!r}",
        )
        _range(self, "across", "scene.obstacles.across")
        _non_negative(self.min_gap, "scene.obstacles.min_gap")
        _finite(self.near_turns, "scene.obstacles.near_turns")
        _require(
            0.0 <= self.near_turns <= 1.0,
            "scene.obstacles.near_turns",
            f"is a probability, must lie in [0, 1], got {self.near_turns!r}",
        )
        _non_negative(self.clear_start, "scene.obstacles.clear_start")


@dataclass(frozen=True)
class RouteConfig:
    """A random preset route: ``legs`` straight legs flown at one speed, each turning by ``turn``
    from the last. The legs' durations are drawn from ``leg_duration`` and then scaled together
    so that they fill ``Scenario.duration`` exactly (only their ratios survive). Velocities are
    horizontal; the first leg's is also the initial velocity.
    """

    legs: tuple[int, int] = (2, 5)  # number of legs, inclusive range [-]
    heading: tuple[float, float] = (0.0, 0.0)  # first leg's heading, anticlockwise from +x [deg]
    turn: tuple[float, float] = (-90.0, 90.0)  # heading change from one leg to the next [deg]
    leg_duration: tuple[float, float] = (30.0, 70.0)  # before scaling to the duration [s]
    speed: tuple[float, float] = (20.0, 20.0)  # one speed for the whole route [m/s]

    def __post_init__(self) -> None:
        legs = _range(self, "legs", "scene.route.legs", int)
        _require(legs[0] >= 1, "scene.route.legs", f"must be >= 1, got {legs!r}")
        _range(self, "heading", "scene.route.heading")
        _range(self, "turn", "scene.route.turn")
        leg_duration = _range(self, "leg_duration", "scene.route.leg_duration")
        _require(
            leg_duration[0] > 0,
            "scene.route.leg_duration",
            f"must be > 0, got {leg_duration!r}",
        )
        speed = _range(self, "speed", "scene.route.speed")
        _require(speed[0] > 0, "scene.route.speed", f"must be > 0, got {speed!r}")


@dataclass(frozen=True)
class SceneConfig:
    """What changes from one reset to the next (:func:`uav_formation_env.scenes.draw_scene`).

    The scenario holding it is the *template*; a scene draws a concrete scenario from it. Every
    range is inclusive and drawn uniformly; ``None`` keeps the template's value.

    - ``n_uav``: N. With ``shapes`` None the formation is the template's first N slots (so the
      template must have at least the largest N), with a k-nearest graph unless N is the
      template's own.
    - ``shapes``: a shape of :data:`FORMATION_SHAPES` drawn uniformly (list one twice to weigh
      it), at a ``spacing`` [m] drawn from its range, with a ``neighbours``-nearest graph.
    - ``obstacles``: an :class:`ObstacleFieldConfig` along the (drawn) route.
    - ``wind``: a horizontal constant wind of magnitude in the range, direction uniform [m/s^2];
      ``gust_std``: the gust std [m/s^2]; ``amplitude``: eq. 21's amplitude [m/s^2].
    - ``route``: a :class:`RouteConfig` replacing the preset schedule.
    """

    n_uav: tuple[int, int] | None = None  # number of UAVs N, inclusive range [-]
    shapes: tuple[str, ...] | None = None  # formation shapes, one drawn uniformly
    spacing: tuple[float, float] = (10.0, 10.0)  # spacing of a drawn shape [m]
    neighbours: int = 4  # k of the k-nearest communication graph of a drawn formation [-]
    obstacles: ObstacleFieldConfig | None = None  # random obstacle field
    wind: tuple[float, float] | None = None  # horizontal wind magnitude [m/s^2]
    gust_std: tuple[float, float] | None = None  # gust std per axis [m/s^2]
    amplitude: tuple[float, float] | None = None  # eq. 21 amplitude [m/s^2]
    route: RouteConfig | None = None  # random preset route

    def __post_init__(self) -> None:
        if self.n_uav is not None:
            n_uav = _range(self, "n_uav", "scene.n_uav", int)
            _require(n_uav[0] >= 2, "scene.n_uav", f"needs at least 2 UAVs, got {n_uav!r}")
        if self.shapes is not None:
            shapes = _as_tuple(self, "shapes", "scene.shapes")
            _require(len(shapes) > 0, "scene.shapes", "must name at least one shape")
            for shape in shapes:
                _require(
                    shape in FORMATION_SHAPES,
                    "scene.shapes",
                    f"must be in {FORMATION_SHAPES}, got {shape!r}",
                )
        spacing = _range(self, "spacing", "scene.spacing")
        _require(spacing[0] > 0, "scene.spacing", f"must be > 0, got {spacing!r}")
        _require(
            isinstance(self.neighbours, int | np.integer)
            and not isinstance(self.neighbours, bool)
            and self.neighbours >= 1,
            "scene.neighbours",
            f"must be an integer >= 1, got {self.neighbours!r}",
        )
        for name in ("wind", "gust_std", "amplitude"):
            if getattr(self, name) is not None:
                bounds = _range(self, name, f"scene.{name}")
                _require(bounds[0] >= 0, f"scene.{name}", f"must be >= 0, got {bounds!r}")
        _require(
            self.obstacles is None or isinstance(self.obstacles, ObstacleFieldConfig),
            "scene.obstacles",
            f"must be an ObstacleFieldConfig or None, got {self.obstacles!r}",
        )
        _require(
            self.route is None or isinstance(self.route, RouteConfig),
            "scene.route",
            f"must be a RouteConfig or None, got {self.route!r}",
        )


def _route_extent(schedule: ScheduleConfig, duration: float) -> tuple[float, int]:
    """Horizontal length [m] of the preset route over [0, duration] and its number of legs."""
    starts = (0.0, *schedule.times)
    ends = (*schedule.times, math.inf)
    length, legs = 0.0, 0
    for start, end, velocity in zip(starts, ends, schedule.velocities):
        flown = min(end, duration) - max(start, 0.0)
        if flown > 0:
            length += math.hypot(velocity[0], velocity[1]) * flown
            legs += 1
    return length, legs


# the NFTSMO's explicit inner ticks stay bounded for h (rho + eta + pi2) up to this (measured:
# the paper's gains diverge at h = 0.2 s, i.e. 0.9; docs/deviations.md)
OBSERVER_TICK_BOUND = 0.5


def _check_observer_tick(scenario: Scenario) -> None:
    """The observer's tick h = dt / substeps short enough for its gains (else NaN estimates)."""
    o = scenario.observer
    if not o.enabled:
        return
    h, gain = scenario.dynamics.dt / o.substeps, o.rho + o.eta + o.pi2
    needed = math.ceil(scenario.dynamics.dt * gain / OBSERVER_TICK_BOUND)
    _require(
        h * gain <= OBSERVER_TICK_BOUND,
        "observer.substeps",
        f"the observer's tick dynamics.dt / observer.substeps = {h:g} s must be <= "
        f"{OBSERVER_TICK_BOUND / gain:.3g} s for its gains (h (rho + eta + pi2) <= "
        f"{OBSERVER_TICK_BOUND}, else its estimate diverges); use observer.substeps >= {needed}",
    )


def _check_start_box_clear(scenario: Scenario) -> None:
    """No obstacle (the scenario's own; drawn ones are placed clear of the start) reaches into
    the horizontal start box."""
    low, high = scenario.initial.position_low, scenario.initial.position_high
    for k, obstacle in enumerate(scenario.avoidance.obstacles):
        x, y = obstacle.center
        dx = max(low[0] - x, 0.0, x - high[0])
        dy = max(low[1] - y, 0.0, y - high[1])
        _require(
            math.hypot(dx, dy) >= obstacle.radius,
            f"avoidance.obstacles[{k}]",
            f"the cylinder at {obstacle.center} of radius {obstacle.radius} m reaches into the "
            f"start box {low}..{high}: UAVs would start inside it",
        )


_HINTS: dict[type, dict[str, typing.Any]] = {}


def _check_types(obj: object, prefix: str) -> None:
    """Every field of a config dataclass tree has its declared kind (a config of the field's
    class, a bool, an integer, a string, a sequence), so that ``Scenario(...)`` built by hand
    fails with the field's name instead of an error deep inside."""
    cls = type(obj)
    hints = _HINTS.get(cls)
    if hints is None:
        hints = _HINTS[cls] = typing.get_type_hints(cls)
    for f in fields(obj):
        value, hint, name = getattr(obj, f.name), hints[f.name], prefix + f.name
        args = typing.get_args(hint)
        if value is None and type(None) in args:
            continue
        kinds = [a for a in args if a is not type(None)] if args and type(None) in args else [hint]
        kind = kinds[0] if len(kinds) == 1 else None
        origin = typing.get_origin(kind)
        if isinstance(kind, type) and is_dataclass(kind):
            _require(
                isinstance(value, kind),
                name,
                f"must be a {kind.__name__}, got {type(value).__name__} {value!r:.60}",
            )
            _check_types(value, name + ".")
        elif kind is bool:
            _require(isinstance(value, bool | np.bool_), name, f"must be true/false, got {value!r}")
        elif kind is int:
            ok = isinstance(value, int | np.integer) and not isinstance(value, bool)
            _require(ok, name, f"must be an integer, got {value!r}")
        elif kind is str:
            _require(isinstance(value, str), name, f"must be a string, got {value!r}")
        elif origin is tuple:
            _require(isinstance(value, tuple | list), name, f"must be a sequence, got {value!r}")


def _check_scene(scenario: Scenario) -> None:
    """The draw-time impossibilities of ``scenario.scene`` that its template already shows."""
    scene = scenario.scene
    if scene is None:
        return
    _require(
        isinstance(scene, SceneConfig),
        "scene",
        f"must be a SceneConfig or None, got {scene!r}",
    )
    if scene.n_uav is not None and scene.shapes is None:
        _require(
            scene.n_uav[1] <= scenario.n_uav,
            "scene.n_uav",
            f"without scene.shapes the formation is the template's first N slots, but the "
            f"template has {scenario.n_uav} UAVs < {scene.n_uav[1]}; give scene.shapes",
        )
    field_ = scene.obstacles
    if field_ is None:
        return
    if scene.route is None:
        length, legs = _route_extent(scenario.schedule, scenario.duration)
    else:  # the longest route any draw gives
        length, legs = scene.route.speed[1] * scenario.duration, scene.route.legs[1]
    _require(
        length > 0 or field_.count[1] == 0,
        "scene.obstacles",
        "the preset route has zero length: no obstacle can be placed along it",
    )
    farthest = field_.along[1] * length + max(abs(a) for a in field_.across)
    _require(
        field_.count[1] == 0 or farthest >= field_.clear_start,
        "scene.obstacles.clear_start",
        f"no centre can be {field_.clear_start} m from the route start: the farthest "
        f"is {farthest:.1f} m",
    )
    # Centres are pairwise >= d apart, so discs of radius d/2 around them are disjoint and lie
    # within d/2 of the region the centres are drawn in: one rectangle (leg part x across
    # width) per leg. More obstacles than those grown rectangles hold discs can never be placed.
    d = 2 * (field_.radius[0] + scenario.avoidance.detection_margin) + field_.min_gap
    span = (field_.along[1] - field_.along[0]) * length
    width = field_.across[1] - field_.across[0]
    room = (span + legs * d) * (width + d) / (math.pi * d * d / 4)
    _require(
        field_.count[1] <= room,
        "scene.obstacles.count",
        f"at most {math.floor(room)} obstacles fit along the route with non-overlapping "
        f"detection circles, but up to {field_.count[1]} are asked for",
    )


@dataclass(frozen=True)
class Scenario:
    """A whole scenario. The defaults are the paper's (docs/model.md §8).

    With a ``scene`` (:class:`SceneConfig`) the scenario is a *template*:
    :func:`uav_formation_env.scenes.draw_scene` draws a concrete scenario from it (``scene``
    None) at each reset, and validation here also rejects scenes the template cannot hold.
    """

    name: str = "paper"
    duration: float = 200.0  # episode length [s]
    dynamics: DynamicsConfig = field(default_factory=DynamicsConfig)
    disturbance: DisturbanceConfig = field(default_factory=DisturbanceConfig)
    observer: ObserverConfig = field(default_factory=ObserverConfig)
    formation: FormationConfig = field(default_factory=FormationConfig)
    avoidance: AvoidanceConfig = field(default_factory=AvoidanceConfig)
    cost: CostConfig = field(default_factory=CostConfig)
    schedule: ScheduleConfig = field(default_factory=ScheduleConfig)
    initial: InitialStateConfig = field(default_factory=InitialStateConfig)
    collision: CollisionConfig = field(default_factory=CollisionConfig)
    mission: MissionConfig = field(default_factory=MissionConfig)
    episode: EpisodeConfig = field(default_factory=EpisodeConfig)
    observation: ObservationConfig = field(default_factory=ObservationConfig)
    # what a reset draws anew (uav_formation_env.scenes.draw_scene); None: a concrete scenario
    scene: SceneConfig | None = None

    def __post_init__(self) -> None:
        _check_types(self, "")
        _positive(self.duration, "duration")
        capacity = self.initial.sampler_capacity()
        _require(
            self.n_uav <= capacity,
            "initial.min_spacing",
            f"{self.n_uav} UAVs cannot be {self.initial.min_spacing} m apart in the start box "
            f"{self.initial.position_low}..{self.initial.position_high} (the start sampler "
            f"places at most {capacity}); enlarge the box or lower min_spacing",
        )
        _check_observer_tick(self)
        _check_start_box_clear(self)
        steps = self.duration / self.dynamics.dt
        _require(
            abs(steps - round(steps)) < 1e-6 and round(steps) >= 1,
            "duration",
            f"must be a positive whole number of steps dynamics.dt={self.dynamics.dt}, "
            f"got {self.duration}",
        )
        sensing = self.observation.sensing_radius
        if sensing is not None:
            needed = max(self.cost.separation_distance, self.collision.uav_distance)
            _require(
                sensing >= needed,
                "observation.sensing_radius",
                f"must be >= cost.separation_distance and collision.uav_distance ({needed:g} m), "
                f"so that J_i and collisions see every close pair, got {sensing!r}",
            )
        _check_scene(self)

    @property
    def n_uav(self) -> int:
        """Number of UAVs N (the template's, for a scenario with a scene)."""
        return self.formation.n_uav

    @property
    def n_steps(self) -> int:
        """Control steps per episode."""
        return int(round(self.duration / self.dynamics.dt))
