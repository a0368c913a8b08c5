"""Tests of scenario distributions (uav_formation_env.scenes): draws, validation, YAML, swarms."""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from uav_formation_env.config import (
    FORMATION_SHAPES,
    InitialStateConfig,
    ObstacleFieldConfig,
    RouteConfig,
    Scenario,
    SceneConfig,
)
from uav_formation_env.config_io import (
    SCENARIOS,
    load_scenario,
    resolve_scenario,
    save_scenario,
    scenario_from_dict,
    to_dict,
    with_overrides,
)
from uav_formation_env.core.initial import initial_positions
from uav_formation_env.formations import SHAPES
from uav_formation_env.scenarios import start_box_for
from uav_formation_env.scenes import (
    draw_scene,
    max_gust_std,
    max_obstacles,
    n_uav_range,
    route_polyline,
)

# every option of a scene at once: a random route, near-turn obstacles, disturbance ranges
FULL_SCENE = SceneConfig(
    n_uav=(3, 8),
    shapes=("wedge", "circle", "grid"),
    spacing=(10.0, 15.0),
    neighbours=3,
    obstacles=ObstacleFieldConfig(count=(2, 3), near_turns=1.0, min_gap=5.0),
    wind=(0.1, 0.2),
    gust_std=(0.0, 0.05),
    amplitude=(0.1, 0.3),
    route=RouteConfig(legs=(2, 4), heading=(-30.0, 30.0), speed=(15.0, 25.0)),
)


def full_template() -> Scenario:
    return Scenario(name="full", scene=FULL_SCENE)


def start_of(scenario: Scenario) -> np.ndarray:
    low, high = scenario.initial.position_low, scenario.initial.position_high
    return (np.asarray(low[:2]) + np.asarray(high[:2])) / 2


def distance_to_polyline(point: np.ndarray, vertices: np.ndarray) -> float:
    """Smallest distance of a point from the segments of a polyline [m]."""
    a, b = vertices[:-1], vertices[1:]
    ab = b - a
    length2 = np.maximum((ab**2).sum(axis=1), 1e-300)
    u = np.clip(((point - a) * ab).sum(axis=1) / length2, 0.0, 1.0)
    return float(np.hypot(*(a + u[:, None] * ab - point).T).min())


def check_obstacles_on_route(drawn: Scenario, field: ObstacleFieldConfig) -> None:
    """The drawn obstacles obey the field: count, radius, distance from the route and start."""
    obstacles = drawn.avoidance.obstacles
    assert field.count[0] <= len(obstacles) <= field.count[1]
    # the drawn field passes AvoidanceConfig's validation when built anew
    dataclasses.replace(drawn.avoidance, obstacles=obstacles)
    vertices = route_polyline(drawn.schedule, start_of(drawn), drawn.duration)
    reach = max(abs(a) for a in field.across)
    for k, o in enumerate(obstacles):
        centre = np.asarray(o.center)
        assert field.radius[0] <= o.radius <= field.radius[1]
        assert distance_to_polyline(centre, vertices) <= reach + 1e-6
        assert math.dist(o.center, vertices[0]) >= field.clear_start
        for other in obstacles[k + 1 :]:
            gap = math.dist(o.center, other.center)
            # detection circles apart, or safety circles with concurrent activation
            need = drawn.avoidance.min_centre_distance(o.radius, other.radius) + field.min_gap
            assert gap >= need - 1e-9


def test_shape_names_match_formations() -> None:
    # config repeats formations.SHAPES (it imports no other module of the package)
    assert FORMATION_SHAPES == SHAPES


# ------------------------------------------------------------------------------------------------
# determinism and draw order
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "make", [SCENARIOS["random_fields"], SCENARIOS["random_swarm"], full_template]
)
def test_same_seed_same_scene(make: Any) -> None:
    template = make()
    for seed in range(5):
        a = draw_scene(template, np.random.default_rng(seed))
        b = draw_scene(template, np.random.default_rng(seed))
        assert a == b
        assert a.scene is None and a.name == template.name


def test_different_seeds_give_different_fields() -> None:
    template = SCENARIOS["random_fields"]()
    fields = {
        draw_scene(template, np.random.default_rng(seed)).avoidance.obstacles for seed in range(20)
    }
    assert len(fields) == 20


def test_no_scene_draws_nothing() -> None:
    paper = resolve_scenario("paper")
    assert paper == Scenario() and paper.scene is None
    rng = np.random.default_rng(7)
    state = rng.bit_generator.state
    assert draw_scene(paper, rng) is paper
    assert rng.bit_generator.state == state
    # the paper's dict form only gained the empty section
    assert to_dict(paper)["scene"] is None
    assert list(to_dict(paper))[-1] == "scene"


@pytest.mark.parametrize("make", [SCENARIOS["random_swarm"], full_template])
def test_n_is_drawn_first(make: Any) -> None:
    template = make()
    low, high = n_uav_range(template)
    for seed in range(30):
        expected = np.random.default_rng(seed).integers(low, high + 1)
        assert draw_scene(template, np.random.default_rng(seed)).n_uav == expected


def test_n_is_drawn_even_for_a_single_value() -> None:
    # n_uav = (5, 5) on a 5-UAV template: one rng.integers call (which numpy makes without using
    # the generator's bits for a one-value range), then the same draws as a scene that leaves N
    # alone
    scene = SceneConfig(shapes=SHAPES, obstacles=ObstacleFieldConfig())
    fixed = Scenario(scene=dataclasses.replace(scene, n_uav=(5, 5)))
    free = Scenario(scene=scene)
    for seed in range(5):
        rng = np.random.default_rng(seed)
        rng.integers(5, 6)
        assert draw_scene(fixed, np.random.default_rng(seed)) == draw_scene(free, rng)


# ------------------------------------------------------------------------------------------------
# what the draws are
# ------------------------------------------------------------------------------------------------


def test_random_fields_draws_are_valid_and_on_the_route() -> None:
    template = SCENARIOS["random_fields"]()
    field = template.scene.obstacles
    counts = set()
    for seed in range(200):
        drawn = draw_scene(template, np.random.default_rng(seed))
        assert isinstance(drawn, Scenario) and drawn.scene is None
        # only the obstacles change: the paper's N, V, graph, route and disturbance
        assert dataclasses.replace(drawn, avoidance=template.avoidance) == dataclasses.replace(
            template, scene=None
        )
        check_obstacles_on_route(drawn, field)
        # the route passes within every obstacle's detection distance: each one is met
        vertices = route_polyline(drawn.schedule, start_of(drawn), drawn.duration)
        for o in drawn.avoidance.obstacles:
            detection = o.radius + drawn.avoidance.detection_margin
            assert distance_to_polyline(np.asarray(o.center), vertices) < detection
        counts.add(len(drawn.avoidance.obstacles))
    assert counts == {1, 2, 3, 4}


def test_random_swarm_draws_are_valid() -> None:
    template = SCENARIOS["random_swarm"]()
    scene = template.scene
    sizes = set()
    for seed in range(200):
        drawn = draw_scene(template, np.random.default_rng(seed))
        assert drawn.scene is None and 3 <= drawn.n_uav <= 10
        assert len(drawn.formation.adjacency) == drawn.n_uav
        check_obstacles_on_route(drawn, scene.obstacles)
        wind = drawn.disturbance.wind
        assert wind[2] == 0.0 and math.hypot(wind[0], wind[1]) <= 0.3 + 1e-12
        assert 0.0 <= drawn.disturbance.gust_std <= 0.1
        assert drawn.schedule == template.schedule
        sizes.add(drawn.n_uav)
    assert sizes == set(range(3, 11))


def test_full_scene_route_and_near_turns() -> None:
    template = full_template()
    field = FULL_SCENE.obstacles
    near = total = 0
    for seed in range(100):
        drawn = draw_scene(template, np.random.default_rng(seed))
        schedule = drawn.schedule
        velocities = np.asarray(schedule.velocities)
        speeds = np.hypot(velocities[:, 0], velocities[:, 1])
        assert 2 <= len(velocities) <= 4
        assert (velocities[:, 2] == 0).all()
        assert np.allclose(speeds, speeds[0]) and 15.0 <= speeds[0] <= 25.0
        assert drawn.initial.velocity == schedule.velocities[0]
        assert all(0 < t < drawn.duration for t in schedule.times)
        # the legs fill the duration together: their durations keep the ratios of the range
        legs = np.diff([0.0, *schedule.times, drawn.duration])
        assert legs.max() / legs.min() <= 70.0 / 30.0 + 1e-9
        vertices = route_polyline(schedule, start_of(drawn), drawn.duration)
        length = np.hypot(*np.diff(vertices, axis=0).T).sum()
        assert length == pytest.approx(speeds[0] * drawn.duration)
        check_obstacles_on_route(drawn, field)
        # near_turns = 1: a centre is within its detection distance (along) and |across| of a
        # turn, unless the turns were too crowded for it
        for o in drawn.avoidance.obstacles:
            reach = o.radius + drawn.avoidance.detection_margin + max(map(abs, field.across))
            near += min(math.dist(o.center, v) for v in vertices[1:-1]) <= reach + 1e-6
            total += 1
        assert 0.1 <= math.hypot(*drawn.disturbance.wind[:2]) <= 0.2
        assert 0.1 <= drawn.disturbance.amplitude <= 0.3
    assert near >= 0.6 * total  # about 0.1 without near_turns


def test_clear_start() -> None:
    field = ObstacleFieldConfig(count=(1, 2), along=(0.0, 0.3), clear_start=400.0)
    template = Scenario(scene=SceneConfig(obstacles=field))
    closest = []
    for seed in range(50):
        drawn = draw_scene(template, np.random.default_rng(seed))
        check_obstacles_on_route(drawn, field)  # centres >= 400 m from the route start
        closest.append(min(math.dist(o.center, (20.0, 0.0)) for o in drawn.avoidance.obstacles))
    assert min(closest) < 450.0  # the bound binds: the start of the route is used up to it


def test_drawn_start_box_holds_n() -> None:
    template = Scenario(scene=SceneConfig(n_uav=(40, 60), shapes=("grid",)))
    for seed in range(5):
        drawn = draw_scene(template, np.random.default_rng(seed))
        initial = drawn.initial
        low, high = np.asarray(initial.position_low), np.asarray(initial.position_high)
        assert np.allclose((low + high)[:2] / 2, (20.0, 0.0))  # the template box's centre
        area = np.prod((high - low)[:2])
        assert area >= drawn.n_uav * (3 * initial.min_spacing) ** 2 - 1.0
        start = time.perf_counter()
        initial_positions(np.random.default_rng(seed), drawn.n_uav, low, high, initial.min_spacing)
        assert time.perf_counter() - start < 0.5


def test_n_without_shapes_takes_the_template_slots() -> None:
    template = Scenario(scene=SceneConfig(n_uav=(3, 5)))
    for seed in range(10):
        drawn = draw_scene(template, np.random.default_rng(seed))
        n = drawn.n_uav
        assert drawn.formation.offsets == template.formation.offsets[:n]
        if n == 5:
            assert drawn.formation == template.formation


def test_helpers() -> None:
    paper = Scenario()
    assert n_uav_range(paper) == (5, 5)
    assert max_obstacles(paper) == 2
    assert max_gust_std(paper) == 0.0
    swarm = SCENARIOS["random_swarm"]()
    assert n_uav_range(swarm) == (3, 10)
    assert max_obstacles(swarm) == 4
    assert max_gust_std(swarm) == 0.1
    assert max_obstacles(Scenario(scene=SceneConfig(n_uav=(2, 3)))) == 2


def test_start_box_for() -> None:
    initial = InitialStateConfig()
    assert start_box_for(initial, 10) is initial  # 40 m x 80 m holds 10 at (15 m)^2 each
    grown = start_box_for(initial, 100)
    low, high = np.asarray(grown.position_low), np.asarray(grown.position_high)
    assert np.allclose((low + high) / 2, (20.0, 0.0, 0.0))
    assert np.prod((high - low)[:2]) >= 100 * 15.0**2 - 1.0
    flat = InitialStateConfig(position_low=(0.0, 0.0, 0.0), position_high=(0.0, 0.0, 0.0))
    grown = start_box_for(flat, 4)
    assert np.allclose(np.subtract(grown.position_high, grown.position_low)[:2], 30.0)


# ------------------------------------------------------------------------------------------------
# YAML, keys and validation
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "make", [SCENARIOS["random_swarm"], SCENARIOS["random_fields"], full_template, Scenario]
)
def test_yaml_round_trip(tmp_path: Path, make: Any) -> None:
    scenario = make()
    path = tmp_path / "scene.yaml"
    save_scenario(scenario, path)
    assert load_scenario(path) == scenario


def test_scene_overrides() -> None:
    s = with_overrides(Scenario(), {"scene.obstacles.count": (2, 3)})
    assert s.scene == SceneConfig(obstacles=ObstacleFieldConfig(count=(2, 3)))
    s = with_overrides(SCENARIOS["random_swarm"](), {"scene__n_uav": [4, 6], "scene.wind": None})
    assert s.scene.n_uav == (4, 6) and s.scene.wind is None and s.scene.shapes == SHAPES
    assert with_overrides(s, {"scene": None}).scene is None


@pytest.mark.parametrize(
    "data, dotted",
    [
        ({"scene": {"obstacles": {"cout": [1, 2]}}}, "scene.obstacles.cout"),
        ({"scene": {"n_uavs": [3, 4]}}, "scene.n_uavs"),
        ({"scene": {"route": {"legz": [1, 2]}}}, "scene.route.legz"),
    ],
)
def test_unknown_scene_keys_are_named(data: dict[str, Any], dotted: str) -> None:
    with pytest.raises(ValueError, match=rf"unknown scenario key '{dotted}'"):
        scenario_from_dict(data)
    with pytest.raises(ValueError, match=rf"'{dotted}'"):
        with_overrides(SCENARIOS["random_swarm"](), {dotted: [1, 2]})


def test_unknown_scene_key_in_yaml(tmp_path: Path) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text("scene:\n  obstacles:\n    cout: [1, 2]\n", encoding="utf-8")
    with pytest.raises(ValueError, match=r"'scene\.obstacles\.cout'"):
        load_scenario(path)


@pytest.mark.parametrize(
    "scene, pattern",
    [
        ({"obstacles": {"count": [3, 1]}}, r"'scene\.obstacles\.count'.*low <= high"),
        ({"obstacles": {"count": [-1, 1]}}, r"'scene\.obstacles\.count'.*>= 0"),
        ({"obstacles": {"count": [1.5, 2]}}, r"'scene\.obstacles\.count'.*integer"),
        ({"obstacles": {"radius": [0.0, 5.0]}}, r"'scene\.obstacles\.radius'"),
        ({"obstacles": {"along": [0.5, 1.5]}}, r"'scene\.obstacles\.along'"),
        ({"obstacles": {"across": [10.0, -10.0]}}, r"'scene\.obstacles\.across'"),
        ({"obstacles": {"near_turns": 2.0}}, r"'scene\.obstacles\.near_turns'"),
        ({"obstacles": {"min_gap": -1.0}}, r"'scene\.obstacles\.min_gap'"),
        ({"obstacles": {"count": [80, 80]}}, r"'scene\.obstacles\.count'.*fit"),
        ({"obstacles": {"clear_start": 5000.0}}, r"'scene\.obstacles\.clear_start'"),
        ({"n_uav": [1, 3], "shapes": ["v"]}, r"'scene\.n_uav'.*at least 2"),
        ({"n_uav": [6, 4], "shapes": ["v"]}, r"'scene\.n_uav'.*low <= high"),
        ({"n_uav": [3, 10]}, r"'scene\.n_uav'.*template has 5 UAVs"),
        ({"n_uav": [3]}, r"'scene\.n_uav'"),
        ({"shapes": ["hexagon"]}, r"'scene\.shapes'.*hexagon"),
        ({"shapes": []}, r"'scene\.shapes'"),
        ({"spacing": [0.0, 10.0]}, r"'scene\.spacing'"),
        ({"neighbours": 0}, r"'scene\.neighbours'"),
        ({"wind": [-0.1, 0.2]}, r"'scene\.wind'"),
        ({"gust_std": [0.2, 0.1]}, r"'scene\.gust_std'"),
        ({"amplitude": [0.1, "x"]}, r"'scene\.amplitude'"),
        ({"route": {"legs": [0, 2]}}, r"'scene\.route\.legs'"),
        ({"route": {"speed": [0.0, 10.0]}}, r"'scene\.route\.speed'"),
        ({"route": {"leg_duration": [0.0, 10.0]}}, r"'scene\.route\.leg_duration'"),
        ({"route": {"turn": [90.0, -90.0]}}, r"'scene\.route\.turn'"),
    ],
)
def test_bad_scenes_name_the_field(scene: dict[str, Any], pattern: str) -> None:
    with pytest.raises(ValueError, match=pattern):
        scenario_from_dict({"scene": scene})


def test_direct_construction_validates() -> None:
    with pytest.raises(ValueError, match=r"'scene\.obstacles\.count'"):
        ObstacleFieldConfig(count=(2, 1))
    with pytest.raises(ValueError, match=r"'scene\.shapes'"):
        SceneConfig(shapes=("square",))
    with pytest.raises(ValueError, match=r"'scene\.n_uav'"):
        Scenario(scene=SceneConfig(n_uav=(2, 6)))
    # lists become tuples: the scene stays hashable
    assert hash(SceneConfig(shapes=["v"], n_uav=[2, 3]))  # type: ignore[arg-type]


def test_crowded_field_gives_a_clear_error() -> None:
    # three obstacles on one point: the up-front bound cannot see it, the draw gives up
    field = ObstacleFieldConfig(count=(3, 3), along=(0.5, 0.5), across=(0.0, 0.0))
    template = Scenario(scene=SceneConfig(obstacles=field))
    with pytest.raises(ValueError, match=r"'scene\.obstacles'.*obstacle 2 of 3"):
        draw_scene(template, np.random.default_rng(0))


# ------------------------------------------------------------------------------------------------
# large swarms
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("n", [20, 50, 100])
def test_swarms(n: int) -> None:
    s = resolve_scenario(f"swarm_{n}")
    assert s.n_uav == n and s.scene is None and s.name == f"swarm_{n}"
    assert s == scenario_from_dict(to_dict(s))  # validates again
    adjacency = np.asarray(s.formation.adjacency)
    assert (adjacency == adjacency.T).all() and adjacency.sum(axis=1).min() >= 1
    across = [row[1] for row in s.formation.offsets]
    assert max(across) - min(across) <= 100.0  # compact: a V of 100 would be 1 km wide
    initial = s.initial
    low, high = np.asarray(initial.position_low), np.asarray(initial.position_high)
    start = time.perf_counter()
    initial_positions(np.random.default_rng(0), n, low, high, initial.min_spacing)
    assert time.perf_counter() - start < 0.5
    # the preset route meets every obstacle, and none lies in the start box's reach
    vertices = route_polyline(s.schedule, start_of(s), s.duration)
    assert len(s.avoidance.obstacles) == 2
    for o in s.avoidance.obstacles:
        detection = o.radius + s.avoidance.detection_margin
        assert distance_to_polyline(np.asarray(o.center), vertices) < detection
        assert o.center[0] - detection > high[0]
