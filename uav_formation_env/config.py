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
from dataclasses import dataclass, field

import numpy as np

Vec3 = tuple[float, float, float]


def _require(condition: bool, field_name: str, rule: str) -> None:
    if not condition:
        raise ValueError(f"invalid scenario field '{field_name}': {rule}")


def _finite(value: float, field_name: str) -> None:
    _require(math.isfinite(value), field_name, f"must be finite, got {value!r}")


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
        matrix = np.asarray(adjacency, dtype=float)
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

    def __post_init__(self) -> None:
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
                reach = oa.radius + ob.radius + 2 * self.detection_margin
                _require(
                    gap >= reach,
                    "avoidance.obstacles",
                    f"obstacles {a} and {b} overlap: their detection circles need centres "
                    f">= {reach:.1f} m apart, got {gap:.1f} m",
                )

    def safety_radius(self, obstacle: ObstacleConfig) -> float:
        """R_s of one obstacle [m]."""
        return obstacle.radius + self.safety_margin


@dataclass(frozen=True)
class CostConfig:
    """Weights and horizon of the game cost J_i (eq. 6, docs/model.md §4).

    ``separation`` and ``separation_distance`` add a term the paper does not have (see
    docs/deviations.md): ``s Σ_{j≠i} max(0, d_s - ||p_i - p_j||)²`` over every other UAV (sensed,
    not only neighbours), at k = 0..H. It is zero whenever all UAVs are at least d_s apart, e.g. in
    the paper's formation (spacing >= 22.4 m). ``separation = 0`` gives the paper's J_i.
    """

    q: float = 1.0  # formation error weight, k = 0..H-1 [1/m^2]
    r: float = 5.0  # control energy weight [s^4/m^2]
    m: float = 1.0  # terminal formation error weight [1/m^2]
    n: float = 10.0  # preset-velocity weight, k = 0..H [s^2/m^2]
    horizon: int = 5  # prediction horizon N (inputs u(0..N-1), terminal state at N) [steps]
    separation: float = 30.0  # s, weight of the separation penalty [1/m^2]
    separation_distance: float = 10.0  # d_s, pairs closer are penalised [m]

    def __post_init__(self) -> None:
        for name in ("q", "r", "m", "n", "separation", "separation_distance"):
            _non_negative(getattr(self, name), f"cost.{name}")
        _require(
            isinstance(self.horizon, int) and self.horizon >= 1,
            "cost.horizon",
            f"must be an integer >= 1, got {self.horizon!r}",
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

    def __post_init__(self) -> None:
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
    mode: str = "none"  # "none" (report only), "penalty" (reward -= penalty), "terminate"
    penalty: float = 1000.0  # cost added on a collision step in "penalty" mode [-]

    def __post_init__(self) -> None:
        _non_negative(self.uav_distance, "collision.uav_distance")
        _require(
            self.mode in ("none", "penalty", "terminate"),
            "collision.mode",
            f"must be 'none', 'penalty' or 'terminate', got {self.mode!r}",
        )
        _non_negative(self.penalty, "collision.penalty")


REWARD_TRANSFORMS = ("raw", "scaled", "log1p")
START_MODES = ("zero", "random", "staggered")
START_CONTROLLERS = ("heuristic",)


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
    """

    reward: str = "raw"  # "raw", "scaled" or "log1p"
    reward_scale: float = 1.0  # J_0 of "scaled" and "log1p" [-]
    max_formation_error: float = 0.0  # divergence bound on a UAV's formation error [m]; 0 = off
    max_velocity_error: float = 0.0  # divergence bound on |v_i - v^d_i| [m/s]; 0 = off
    corridor_width: float = 0.0  # half-width of the corridor around the preset route [m]; 0 = off
    corridor_penalty: float = 0.0  # cost added to each agent on leaving the corridor [-]
    start: str = "zero"  # "zero", "random" or "staggered": where along the mission episodes start
    start_controller: str = "heuristic"  # flies a copy to its start step

    def __post_init__(self) -> None:
        _require(
            self.reward in REWARD_TRANSFORMS,
            "episode.reward",
            f"must be one of {REWARD_TRANSFORMS}, got {self.reward!r}",
        )
        _positive(self.reward_scale, "episode.reward_scale")
        _non_negative(self.max_formation_error, "episode.max_formation_error")
        _non_negative(self.max_velocity_error, "episode.max_velocity_error")
        _non_negative(self.corridor_width, "episode.corridor_width")
        _non_negative(self.corridor_penalty, "episode.corridor_penalty")
        _require(
            self.start in START_MODES,
            "episode.start",
            f"must be one of {START_MODES}, got {self.start!r}",
        )
        _require(
            self.start_controller in START_CONTROLLERS,
            "episode.start_controller",
            f"must be one of {START_CONTROLLERS}, got {self.start_controller!r}",
        )


@dataclass(frozen=True)
class Scenario:
    """A whole scenario. The defaults are the paper's (docs/model.md §8)."""

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

    def __post_init__(self) -> None:
        _positive(self.duration, "duration")
        capacity = self.initial.capacity()
        _require(
            self.n_uav <= capacity,
            "initial.min_spacing",
            f"{self.n_uav} UAVs cannot be {self.initial.min_spacing} m apart in the start box "
            f"{self.initial.position_low}..{self.initial.position_high} (room for at most "
            f"{capacity:.0f}); enlarge the box or lower min_spacing",
        )
        steps = self.duration / self.dynamics.dt
        _require(
            abs(steps - round(steps)) < 1e-6 and round(steps) >= 1,
            "duration",
            f"must be a positive whole number of steps dynamics.dt={self.dynamics.dt}, "
            f"got {self.duration}",
        )

    @property
    def n_uav(self) -> int:
        """Number of UAVs N."""
        return self.formation.n_uav

    @property
    def n_steps(self) -> int:
        """Control steps per episode."""
        return int(round(self.duration / self.dynamics.dt))
