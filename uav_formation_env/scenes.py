"""Scenario distributions: a concrete scenario drawn from a template at each reset.

A :class:`~uav_formation_env.config.Scenario` whose ``scene`` is a
:class:`~uav_formation_env.config.SceneConfig` is a *template*. :func:`draw_scene` draws from it,
with the caller's generator, a concrete scenario (``scene`` None): the number of UAVs, the
formation, the preset route, the disturbance and an obstacle field
(:class:`~uav_formation_env.config.ObstacleFieldConfig`) along the route. The configuration
classes live in :mod:`uav_formation_env.config` (the scenario holds them, and config imports no
other module of the package) and are re-exported here.

Draw order (one generator, so the same state gives the same scene):

1. N: exactly one ``rng.integers(low, high + 1)`` when ``scene.n_uav`` is set, even for
   ``low == high``, so that a caller can tell N (and size its buffers) from the generator alone;
2. the shape (``rng.integers``) and its spacing (``rng.uniform``), when ``scene.shapes`` is set;
3. the route (legs, first heading, speed, turns, leg durations), when ``scene.route`` is set;
4. the wind magnitude and direction, the gust std, the eq. 21 amplitude, each when set;
5. the obstacles last (their count, then each obstacle until it fits), since rejection makes
   the number of draws vary.

Nothing is drawn for a scenario without a scene: it is returned as it is.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from uav_formation_env.config import (
    AvoidanceConfig,
    DisturbanceConfig,
    FormationConfig,
    ObstacleConfig,
    ObstacleFieldConfig,
    RouteConfig,
    Scenario,
    SceneConfig,
    ScheduleConfig,
)
from uav_formation_env.core.reference import preset_displacement
from uav_formation_env.formations import k_nearest_adjacency
from uav_formation_env.scenarios import shape_formation, start_box_for

__all__ = [
    "MAX_TRIES",
    "ObstacleFieldConfig",
    "RouteConfig",
    "SceneConfig",
    "draw_scene",
    "max_gust_std",
    "max_route_legs",
    "max_obstacles",
    "n_uav_range",
    "route_polyline",
    "scene_of_seed",
    "seeds_by_n_uav",
]

MAX_TRIES = 1000  # placements tried per obstacle before the field is given up as too crowded
_MIN_LENGTH = 1e-9  # route segments shorter than this have no heading [m]


def n_uav_range(scenario: Scenario) -> tuple[int, int]:
    """Smallest and largest N any draw of ``scenario`` can have (the template's N twice when
    the scene leaves N alone)."""
    scene = scenario.scene
    if scene is None or scene.n_uav is None:
        return scenario.n_uav, scenario.n_uav
    return scene.n_uav


def max_obstacles(scenario: Scenario) -> int:
    """The largest obstacle count any draw of ``scenario`` can have (the template's count when
    the scene leaves the obstacles alone)."""
    scene = scenario.scene
    if scene is None or scene.obstacles is None:
        return len(scenario.avoidance.obstacles)
    return scene.obstacles.count[1]


def max_gust_std(scenario: Scenario) -> float:
    """The largest gust std any draw of ``scenario`` can have [m/s^2] (the template's when the
    scene leaves the gusts alone)."""
    scene = scenario.scene
    if scene is None or scene.gust_std is None:
        return scenario.disturbance.gust_std
    return float(scene.gust_std[1])


def max_route_legs(scenario: Scenario) -> int | None:
    """The largest leg count of a route drawn per scene (None: every copy flies the template's
    schedule)."""
    scene = scenario.scene
    if scene is None or scene.route is None:
        return None
    return scene.route.legs[1]


def route_polyline(schedule: ScheduleConfig, start: np.ndarray, duration: float) -> np.ndarray:
    """Horizontal vertices of the preset route flown from ``start`` over ``[0, duration]``.

    The route is ``start`` plus :func:`~uav_formation_env.core.reference.preset_displacement`
    (as in :mod:`uav_formation_env.evaluation.mission`); it is straight between switching times.

    Args:
        schedule: the preset velocity (eq. 23).
        start: (2,) or (3,) route position at t = 0 [m].
        duration: episode length [s].

    Returns:
        (M, 2) vertices [m]: t = 0, each switching time inside (0, duration), and t = duration.
    """
    inside = [t for t in schedule.times if 0.0 < t < duration]
    breakpoints = np.array([0.0, *inside, duration])
    return np.asarray(start, dtype=float)[:2] + preset_displacement(schedule, breakpoints)[:, :2]


def _draw_formation(
    scenario: Scenario, scene: SceneConfig, n: int, rng: np.random.Generator
) -> FormationConfig:
    """The formation of a draw (shape and spacing drawn here when ``scene.shapes`` is set)."""
    template = scenario.formation
    if scene.shapes is not None:
        shape = scene.shapes[int(rng.integers(len(scene.shapes)))]
        spacing = float(rng.uniform(*scene.spacing))
        formation = shape_formation(shape, n, spacing, int(scene.neighbours))
        return replace(formation, mirrored_offsets=template.mirrored_offsets)
    if n == template.n_uav:
        return template
    # the template's first N slots (Scenario validation checked it has that many); its graph
    # restricted to them may not have a spanning tree, so they get a k-nearest one
    offsets = template.offsets[:n]
    adjacency = k_nearest_adjacency(np.asarray(offsets), int(scene.neighbours))
    return FormationConfig(
        offsets,
        tuple(tuple(row) for row in adjacency.tolist()),
        template.mirrored_offsets,
    )


def _draw_route(route: RouteConfig, duration: float, rng: np.random.Generator) -> ScheduleConfig:
    """A preset schedule of straight horizontal legs at one speed, filling ``duration``."""
    legs = int(rng.integers(route.legs[0], route.legs[1] + 1))
    heading = math.radians(float(rng.uniform(*route.heading)))
    speed = float(rng.uniform(*route.speed))
    turns = np.radians(rng.uniform(*route.turn, size=legs - 1))
    lengths = rng.uniform(*route.leg_duration, size=legs)  # [s], > 0 by validation
    headings = heading + np.concatenate(([0.0], np.cumsum(turns)))
    # scaled together so that the last leg ends with the episode: the route's length is then
    # speed x duration whatever the draw
    times = np.cumsum(lengths)[:-1] * (duration / lengths.sum())
    velocities = tuple((speed * math.cos(h), speed * math.sin(h), 0.0) for h in headings.tolist())
    return ScheduleConfig(tuple(times.tolist()), velocities)


def _draw_disturbance(
    template: DisturbanceConfig, scene: SceneConfig, rng: np.random.Generator
) -> DisturbanceConfig:
    """The template's disturbance with the scene's wind, gust std and amplitude drawn."""
    changes: dict[str, object] = {}
    if scene.wind is not None:
        magnitude = float(rng.uniform(*scene.wind))  # [m/s^2]
        direction = float(rng.uniform(0.0, 2.0 * math.pi))
        changes["wind"] = (magnitude * math.cos(direction), magnitude * math.sin(direction), 0.0)
    if scene.gust_std is not None:
        changes["gust_std"] = float(rng.uniform(*scene.gust_std))
    if scene.amplitude is not None:
        changes["amplitude"] = float(rng.uniform(*scene.amplitude))
    return replace(template, **changes) if changes else template


def _draw_obstacles(
    field: ObstacleFieldConfig,
    vertices: np.ndarray,
    avoidance: AvoidanceConfig,
    rng: np.random.Generator,
) -> tuple[ObstacleConfig, ...]:
    """An obstacle field along the route ``vertices`` (see :class:`ObstacleFieldConfig`).

    Raises:
        ValueError: naming ``scene.obstacles`` when an obstacle found no place in
            :data:`MAX_TRIES` tries.
    """
    count = int(rng.integers(field.count[0], field.count[1] + 1))
    if count == 0:
        return ()
    steps = np.diff(vertices, axis=0)
    lengths = np.hypot(steps[:, 0], steps[:, 1])
    keep = lengths > _MIN_LENGTH  # a zero-length leg (zero velocity) has no direction
    starts, steps, lengths = vertices[:-1][keep], steps[keep], lengths[keep]
    if len(lengths) == 0:
        raise ValueError(
            "invalid scenario field 'scene.obstacles': the preset route has zero length"
        )
    units = steps / lengths[:, None]
    arc = np.concatenate(([0.0], np.cumsum(lengths)))  # arc length at each segment start [m]
    low, high = field.along[0] * arc[-1], field.along[1] * arc[-1]
    # turns: where one kept segment meets the next at an angle; only those inside the along
    # range can take a near-turn obstacle
    a, b = units[:-1], units[1:]
    bends = (np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]) > 1e-9) | ((a * b).sum(axis=1) < 0)
    turns = [s for s in arc[1:-1][bends].tolist() if low <= s <= high]
    origin = vertices[0]
    placed: list[tuple[float, ObstacleConfig]] = []  # (arc length, obstacle)
    for k in range(count):
        for tries in range(MAX_TRIES):
            radius = float(rng.uniform(*field.radius))
            # a few turns hold few obstacles: after half the tries, any place along the route
            # will do, so that near_turns never makes a field impossible
            near = field.near_turns > 0 and turns and tries < MAX_TRIES // 2
            if near and rng.random() < field.near_turns:
                turn = turns[int(rng.integers(len(turns)))]
                reach = radius + avoidance.detection_margin  # the detection circle covers it
                s = float(np.clip(turn + rng.uniform(-reach, reach), low, high))
            else:
                s = float(rng.uniform(low, high))
            offset = float(rng.uniform(*field.across))
            leg = min(int(np.searchsorted(arc, s, side="right")) - 1, len(lengths) - 1)
            point = starts[leg] + (s - arc[leg]) * units[leg]
            normal = np.array([-units[leg, 1], units[leg, 0]])  # left of the direction of flight
            centre = (float(point[0] + offset * normal[0]), float(point[1] + offset * normal[1]))
            if math.dist(centre, origin) < field.clear_start:
                continue
            # AvoidanceConfig's rule, computed as it does (math.dist on the stored floats), plus
            # min_gap: the drawn field passes its validation
            if all(
                math.dist(centre, other.center)
                >= avoidance.min_centre_distance(radius, other.radius) + field.min_gap
                for _, other in placed
            ):
                placed.append((s, ObstacleConfig(centre, radius)))
                break
        else:
            circles = "safety" if avoidance.concurrent else "detection"
            raise ValueError(
                "invalid scenario field 'scene.obstacles': could not place obstacle "
                f"{k + 1} of {count} after {MAX_TRIES} tries ({circles} circles must not "
                f"overlap and centres must be >= {field.clear_start} m from the route start); "
                "widen along/across or lower count, radius, min_gap or clear_start"
            )
    # in the order the route meets them
    return tuple(obstacle for _, obstacle in sorted(placed, key=lambda item: item[0]))


def draw_scene(scenario: Scenario, rng: np.random.Generator) -> Scenario:
    """A concrete scenario drawn from the template ``scenario`` (see the module docstring).

    Pure: the result depends on ``scenario`` and the state of ``rng`` only. Fields the scene
    does not draw keep the template's values; the name is kept and ``scene`` is None.

    Args:
        scenario: the template; without a scene it is returned as it is, and nothing is drawn.
        rng: the generator to draw from (the env copy's own).

    Returns:
        A validated scenario with ``scene=None``.

    Raises:
        ValueError: an obstacle field that found no room (naming ``scene.obstacles``).
    """
    scene = scenario.scene
    if scene is None:
        return scenario
    n = scenario.n_uav
    if scene.n_uav is not None:  # first, and always exactly one call (module docstring)
        n = int(rng.integers(scene.n_uav[0], scene.n_uav[1] + 1))
    formation = _draw_formation(scenario, scene, n, rng)
    initial = scenario.initial
    if formation is not scenario.formation:
        initial = start_box_for(initial, n)
    schedule = scenario.schedule
    if scene.route is not None:
        schedule = _draw_route(scene.route, scenario.duration, rng)
        initial = replace(initial, velocity=schedule.velocities[0])
    disturbance = _draw_disturbance(scenario.disturbance, scene, rng)
    avoidance = scenario.avoidance
    if scene.obstacles is not None:
        # the route starts at the start box's centre, the mean of the initial positions
        centre = (np.asarray(initial.position_low) + np.asarray(initial.position_high)) / 2
        vertices = route_polyline(schedule, centre, scenario.duration)
        obstacles = _draw_obstacles(scene.obstacles, vertices, avoidance, rng)
        avoidance = replace(avoidance, obstacles=obstacles)
    return replace(
        scenario,
        formation=formation,
        initial=initial,
        schedule=schedule,
        disturbance=disturbance,
        avoidance=avoidance,
        scene=None,
    )


def scene_of_seed(scenario: Scenario, seed: int) -> tuple[Scenario, np.random.Generator]:
    """The scene a reset with episode seed ``seed`` draws, and the copy's generator after it.

    The one rule of what a seed names: the copy's generator is ``default_rng(seed)``; the scene
    is drawn from it first, then the start positions, gusts and noise
    (:meth:`~uav_formation_env.sim.FormationSim.reset`).
    """
    rng = np.random.default_rng(seed)
    return draw_scene(scenario, rng), rng


def seeds_by_n_uav(scenario: Scenario, seeds: Sequence[int]) -> dict[int, list[int]]:
    """The seeds grouped by the N of the scene each draws, groups in ascending N (one group for
    a scenario of one N): a simulator has one N, so a distribution over N runs one per group."""
    low, high = n_uav_range(scenario)
    if low == high:
        return {low: list(seeds)}
    groups: dict[int, list[int]] = {}
    for seed in seeds:
        groups.setdefault(scene_of_seed(scenario, seed)[0].n_uav, []).append(seed)
    return dict(sorted(groups.items()))
