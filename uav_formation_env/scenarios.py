"""Scenario builders: the paper's, other formation sizes, obstacle fields, wind, swarms.

Formation shapes and obstacle fields are data: every builder returns a validated
:class:`~uav_formation_env.config.Scenario`. Random obstacle fields draw from a passed
``np.random.Generator``.

Named scenarios of this module (registered in :data:`uav_formation_env.config_io.SCENARIOS`;
docs/scenarios.md, "Named scenarios", describes each): ``random_fields`` (the paper with a new
field of 1-4 obstacles each reset), ``random_routes`` (a drawn route of 3-5 legs through 2-5
obstacles), ``random_swarm`` (N in 3..10, a drawn shape, field and wind) and ``swarm_20``,
``swarm_50``, ``swarm_100`` (N UAVs in a 10 m grid on the paper's route, the local observation);
``hold`` and ``track``, the lower rungs of the task ladder (:mod:`uav_formation_env.tasks`): the
paper's formation and disturbance on a straight 60 s route, and on the paper's route, both
without obstacles.

All of them but the paper's fly the avoidance rules of :data:`DRAWN_AVOIDANCE` (and the drawn
ones :data:`DRAWN_CORNERS`; docs/scenarios.md, "The shipped rules"); the drawn scenarios' J_i
has the obstacle clearance term of :data:`DRAWN_COST` (docs/deviations.md §8).

The templates (a :class:`~uav_formation_env.config.SceneConfig` in ``scene``) are concrete
until drawn: :func:`uav_formation_env.scenes.draw_scene` gives the scenario of one reset.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from uav_formation_env.config import (
    PAPER_OBSTACLES,
    AvoidanceConfig,
    DisturbanceConfig,
    FormationConfig,
    InitialStateConfig,
    ObservationConfig,
    ObstacleConfig,
    ObstacleFieldConfig,
    RouteConfig,
    Scenario,
    SceneConfig,
    ScheduleConfig,
)
from uav_formation_env.formations import SHAPES, formation_offsets, k_nearest_adjacency


def v_offsets(n_uav: int, spacing: float = 10.0) -> tuple[tuple[float, ...], ...]:
    """V formation pointing +x (:func:`~uav_formation_env.formations.formation_offsets`):
    apex at 0, then pairs k = 1, 2, … at (-spacing k, ±2 spacing k); for N = 5 and the default
    spacing this is the paper's z^d (eq. 22)."""
    return tuple(tuple(row) for row in formation_offsets("v", n_uav, spacing).tolist())


def leader_chain_adjacency(n_uav: int) -> tuple[tuple[int, ...], ...]:
    """Every UAV receives from UAV 1 (the apex) and from its neighbours in index order."""
    h = np.zeros((n_uav, n_uav), dtype=int)
    h[1:, 0] = 1
    idx = np.arange(n_uav - 1)
    h[idx, idx + 1] = 1
    h[idx + 1, idx] = 1
    np.fill_diagonal(h, 0)
    return tuple(tuple(int(x) for x in row) for row in h)


def random_obstacles(
    rng: np.random.Generator,
    count: int = 3,
    x_range: tuple[float, float] = (250.0, 950.0),
    y_range: tuple[float, float] = (-60.0, 60.0),
    radius_range: tuple[float, float] = (15.0, 35.0),
    detection_margin: float = 40.0,
    max_tries: int = 1000,
) -> tuple[ObstacleConfig, ...]:
    """Obstacles uniform in a box (by default across the first leg of the paper's route).

    Rejection-samples until no two detection circles overlap (the validity rule of
    :class:`~uav_formation_env.config.AvoidanceConfig`).
    """
    placed: list[ObstacleConfig] = []
    for _ in range(max_tries):
        if len(placed) == count:
            break
        candidate = ObstacleConfig(
            (float(rng.uniform(*x_range)), float(rng.uniform(*y_range))),
            float(rng.uniform(*radius_range)),
        )
        if all(
            np.hypot(candidate.center[0] - o.center[0], candidate.center[1] - o.center[1])
            >= candidate.radius + o.radius + 2 * detection_margin
            for o in placed
        ):
            placed.append(candidate)
    if len(placed) < count:
        raise ValueError(f"could not place {count} non-overlapping obstacles in the box")
    return tuple(sorted(placed, key=lambda o: o.center[0]))


def make_scenario(
    n_uav: int = 5,
    obstacles: str = "paper",
    observer: bool = True,
    collision_mode: str = "none",
    seed: int = 0,
    wind: tuple[float, float, float] = (0.0, 0.0, 0.0),
    gust_std: float = 0.0,
    duration: float | None = None,
) -> Scenario:
    """A variant of the paper's scenario.

    Args:
        n_uav: formation size; N = 5 gives the paper's V and graph, others a V with a
            leader-chain graph.
        obstacles: "paper", "none" or "random" (3 obstacles drawn with ``seed``).
        observer: NFTSMO compensation on or off.
        collision_mode: "none", "penalty" or "terminate".
        seed: seed of the random obstacle field.
        wind: constant wind [m/s^2].
        gust_std: Gauss-Markov gust std [m/s^2] (0 = off).
        duration: episode length [s] (None: the paper's 200 s).
    """
    base = Scenario()
    if n_uav == 5:
        formation = base.formation
    else:
        formation = FormationConfig(v_offsets(n_uav), leader_chain_adjacency(n_uav))
    if obstacles == "paper":
        field = base.avoidance.obstacles
    elif obstacles == "none":
        field = ()
    elif obstacles == "random":
        field = random_obstacles(np.random.default_rng(seed))
    else:
        raise ValueError(f"obstacles must be 'paper', 'none' or 'random', got {obstacles!r}")
    return replace(
        base,
        name=f"n{n_uav}_{obstacles}",
        duration=base.duration if duration is None else duration,
        formation=formation,
        avoidance=replace(base.avoidance, obstacles=field),
        observer=replace(base.observer, enabled=observer),
        disturbance=DisturbanceConfig(wind=wind, gust_std=gust_std),
        collision=replace(base.collision, mode=collision_mode),
    )


def windy_scenario() -> Scenario:
    """The paper's scenario with a constant 0.3 m/s² crosswind and 0.1 m/s² gusts."""
    return replace(make_scenario(wind=(0.0, 0.3, 0.0), gust_std=0.1), name="windy")


def start_box_for(initial: InitialStateConfig, n_uav: int) -> InitialStateConfig:
    """``initial`` with its start box grown, about its centre, to hold ``n_uav`` UAVs easily.

    The box gets at least (3 min_spacing)² of horizontal area per UAV, so that the rejection
    sampling of :func:`uav_formation_env.core.initial.initial_positions` (which redraws UAVs
    closer than min_spacing) ends within a few rounds; a box that already has it is kept as it
    is. Both horizontal extents grow by the same factor (a flat extent takes the other's size).
    """
    need = n_uav * (3.0 * initial.min_spacing) ** 2  # [m^2]
    low, high = initial.position_low, initial.position_high
    ex, ey = high[0] - low[0], high[1] - low[1]
    if ex * ey >= need:
        return initial
    if ex > 0 and ey > 0:
        grow = math.sqrt(need / (ex * ey))
        ex, ey = ex * grow, ey * grow
    elif ex > 0:  # a flat box: the flat side opens up to the area needed
        ey = need / ex
    elif ey > 0:
        ex = need / ey
    else:
        ex = ey = math.sqrt(need)
    # half-extents rounded up to 0.1 m: tidy numbers in YAML, and never below the area needed
    hx, hy = math.ceil(ex * 5.0) / 10.0, math.ceil(ey * 5.0) / 10.0
    cx, cy = (low[0] + high[0]) / 2, (low[1] + high[1]) / 2
    return replace(
        initial,
        # rounded: -3.8 rather than -3.8000000000000007 in YAML
        position_low=(round(cx - hx, 6), round(cy - hy, 6), low[2]),
        position_high=(round(cx + hx, 6), round(cy + hy, 6), high[2]),
    )


def shape_formation(
    shape: str, n_uav: int, spacing: float = 10.0, neighbours: int = 4
) -> FormationConfig:
    """A named shape (:func:`~uav_formation_env.formations.formation_offsets`, spacing [m])
    with a ``neighbours``-nearest communication graph
    (:func:`~uav_formation_env.formations.k_nearest_adjacency`)."""
    offsets = formation_offsets(shape, n_uav, spacing)
    adjacency = k_nearest_adjacency(offsets, neighbours)
    return FormationConfig(
        tuple(tuple(row) for row in offsets.tolist()),
        tuple(tuple(row) for row in adjacency.tolist()),
    )


# The avoidance rules of the drawn scenarios and the swarms beyond the paper's (docs/scenarios.md):
# obstacles activate whenever they qualify, also while another is active (an obstacle near a
# turn must not wait for the previous one to be restored), a done obstacle activates again when
# a route turn leads back to it, between avoidances the reference leads the formation back to
# its preset route (0.05 1/s, at most 5 m/s), and within 5 s of a turn an obstacle just past it
# is judged along the next leg (a 90-degree turn at 20 m/s and 5 m/s^2 per axis takes 4 s), with
# sides from each UAV's chord to the next leg there (docs/scenarios.md, "The shipped rules")
DRAWN_AVOIDANCE = {
    "concurrent": True,
    "rearm": True,
    "route_gain": 0.05,
    "route_correction_max": 5.0,
    "turn_preview": 5.0,
}
# the drawn scenarios' only (not swarm_N's): a turn ramps over 4 s and an avoiding group keeps
# the route's pace (at most 1.2 x |v^d|) (docs/scenarios.md, "The shipped rules")
DRAWN_CORNERS = {"turn_blend": 4.0, "pace_limit": 1.2}
# J_i's obstacle clearance term (docs/deviations.md §8): 100 / m² within the 10 m safety margin,
# over the horizon and 2 s of free flight beyond it (10 steps: the 40 m a UAV needs to stop from
# 20 m/s at 5 m/s^2); on random_fields it took the colliding seeds from 14 to 0 of 100
DRAWN_COST = {"obstacle": 100.0, "obstacle_lookahead": 10}
# with concurrent activation only the safety circles must be apart; this much more keeps the
# fields of random_fields and random_swarm as they were (detection circles apart): 60 m [m]
DETECTION_APART = 2 * (AvoidanceConfig().detection_margin - AvoidanceConfig().safety_margin)


def _drawn(name: str, scene: SceneConfig, observation: ObservationConfig | None = None) -> Scenario:
    """The paper's scenario with ``scene`` drawn per reset and the avoidance rules of
    :data:`DRAWN_AVOIDANCE`."""
    base = Scenario()
    return replace(
        base,
        name=name,
        avoidance=replace(base.avoidance, **DRAWN_AVOIDANCE, **DRAWN_CORNERS),
        cost=replace(base.cost, **DRAWN_COST),
        scene=scene,
        observation=base.observation if observation is None else observation,
    )


def random_fields_scenario() -> Scenario:
    """The paper's scenario with a random obstacle field drawn each reset (module docstring)."""
    # the V's half-width: obstacles at most this far to the side still cross the formation
    half_width = max(abs(row[1]) for row in Scenario().formation.offsets)
    field = ObstacleFieldConfig(
        count=(1, 4), across=(-half_width, half_width), min_gap=DETECTION_APART
    )
    return _drawn("random_fields", SceneConfig(obstacles=field))


def random_routes_scenario() -> Scenario:
    """The paper's formation on a drawn route through a dense field (module docstring)."""
    half_width = max(abs(row[1]) for row in Scenario().formation.offsets)
    field = ObstacleFieldConfig(
        count=(2, 5), across=(-half_width, half_width), near_turns=0.5, clear_start=150.0
    )
    scene = SceneConfig(route=RouteConfig(legs=(3, 5), turn=(-90.0, 90.0)), obstacles=field)
    # the route is drawn: only the local layout carries the next leg to the policies
    return _drawn("random_routes", scene, ObservationConfig(kind="local"))


def random_swarm_scenario() -> Scenario:
    """N, shape, obstacle field, wind and gusts drawn each reset (module docstring)."""
    scene = SceneConfig(
        n_uav=(3, 10),
        shapes=SHAPES,
        obstacles=ObstacleFieldConfig(count=(1, 4), min_gap=DETECTION_APART),
        wind=(0.0, 0.3),
        gust_std=(0.0, 0.1),
    )
    # N varies, so only the N-independent observation gives one space for every reset
    return _drawn("random_swarm", scene, ObservationConfig(kind="local"))


SWARM_SENSING_RADIUS = 25.0  # [m], observation.sensing_radius of swarm_scenario


def _box_gap(centre: tuple[float, float], initial: InitialStateConfig) -> float:
    """Horizontal distance from ``centre`` to the start box of ``initial`` [m] (0 inside)."""
    low, high = initial.position_low, initial.position_high
    dx = max(low[0] - centre[0], 0.0, centre[0] - high[0])
    dy = max(low[1] - centre[1], 0.0, centre[1] - high[1])
    return math.hypot(dx, dy)


def swarm_scenario(n_uav: int, shape: str = "grid", spacing: float = 10.0) -> Scenario:
    """N UAVs in a compact shape on the paper's route and obstacles (module docstring).

    Args:
        n_uav: N >= 2.
        shape: one of :data:`~uav_formation_env.formations.SHAPES`.
        spacing: the formation's spacing [m].
    """
    base = Scenario()
    formation = shape_formation(shape, n_uav, spacing)
    across = [row[1] for row in formation.offsets]
    half_width = (max(across) - min(across)) / 2  # [m]
    initial = start_box_for(base.initial, n_uav)
    # the paper's 30 m obstacles against its V of half-width 40 m, scaled to this formation, with
    # their safety circles clear of the start box (which grows with N towards O1)
    clear = min(_box_gap(o.center, initial) for o in PAPER_OBSTACLES)
    radius = min(max(15.0, 30.0 * half_width / 40.0), clear - base.avoidance.safety_margin)
    obstacles = tuple(ObstacleConfig(o.center, radius) for o in PAPER_OBSTACLES)
    return replace(
        base,
        name=f"swarm_{n_uav}",
        formation=formation,
        initial=initial,
        # inside a sub-formation H0's own edges, not the complete graph: with 64 in-neighbours
        # the formation term outweighed the avoidance reference (docs/scenarios.md, swarm_100)
        # not DRAWN_CORNERS: with them swarm_100's grid, faster round O1 and without J_i's
        # obstacle term, had UAVs inside O1 at 12 s (both seeds; docs/scenarios.md)
        avoidance=replace(
            base.avoidance, obstacles=obstacles, split_graph="base", **DRAWN_AVOIDANCE
        ),
        # no obstacle term (DRAWN_COST): in the 10 m grid, UAVs braking for O1 on their own
        # (before the topology splits the grid) are run into from behind (docs/scenarios.md)
        # pair terms within 25 m (2.5 spacings, about 20 UAVs of the grid): linear in N
        observation=ObservationConfig(kind="local", sensing_radius=SWARM_SENSING_RADIUS),
    )


__all__ = [
    "hold_scenario",
    "leader_chain_adjacency",
    "make_scenario",
    "random_fields_scenario",
    "random_obstacles",
    "random_swarm_scenario",
    "shape_formation",
    "start_box_for",
    "swarm_scenario",
    "track_scenario",
    "v_offsets",
    "windy_scenario",
]


def hold_scenario() -> Scenario:
    """The first rung of the task ladder: the paper's formation, disturbance and observer on a
    straight route at the paper's first leg (20 m/s along x) for 60 s, without obstacles."""
    base = Scenario()
    return replace(
        base,
        name="hold",
        duration=60.0,
        schedule=ScheduleConfig(times=(), velocities=(base.schedule.velocities[0],)),
        avoidance=replace(base.avoidance, obstacles=()),
    )


def track_scenario() -> Scenario:
    """The second rung: the paper's route, formation and disturbance without obstacles."""
    return replace(make_scenario(obstacles="none"), name="track")
