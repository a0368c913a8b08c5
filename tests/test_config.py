"""Tests of the scenario configuration: paper defaults, validation, YAML I/O, overrides."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from uav_formation_env.config import (
    AvoidanceConfig,
    CollisionConfig,
    CostConfig,
    DisturbanceConfig,
    DynamicsConfig,
    FormationConfig,
    InitialStateConfig,
    ObserverConfig,
    ObstacleConfig,
    Scenario,
    ScheduleConfig,
    has_directed_spanning_tree,
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

# ------------------------------------------------------------------------------------------------
# paper defaults
# ------------------------------------------------------------------------------------------------


def test_paper_default_scenario() -> None:
    s = Scenario()
    assert s.name == "paper"
    assert s.n_uav == 5
    assert s.n_steps == 1000
    assert s.duration == 200.0 and s.dynamics.dt == 0.2
    assert s.dynamics.u_max == 5.0
    c = s.cost
    assert (c.q, c.r, c.m, c.n, c.horizon) == (1.0, 5.0, 1.0, 10.0, 5)
    # separation term (not in the paper, docs/deviations.md §5): s [1/m^2], d_s [m]
    assert (c.separation, c.separation_distance) == (30.0, 10.0)
    assert s.formation.offsets == (
        (0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        (-10.0, 20.0, 0.0, 0.0, 0.0, 0.0),
        (-10.0, -20.0, 0.0, 0.0, 0.0, 0.0),
        (-20.0, 40.0, 0.0, 0.0, 0.0, 0.0),
        (-20.0, -40.0, 0.0, 0.0, 0.0, 0.0),
    )
    h0 = np.array(s.formation.adjacency)
    np.testing.assert_array_equal(
        h0,
        [[0, 1, 0, 1, 1], [1, 0, 1, 1, 1], [1, 1, 0, 1, 1], [1, 0, 1, 0, 1], [1, 1, 1, 0, 0]],
    )
    # neighbours (1-based), row = receiver: UAV1 {2,4,5}, UAV2 {1,3,4,5}, UAV3 {1,2,4,5}, ...
    neighbours = [set((np.flatnonzero(row) + 1).tolist()) for row in h0]
    assert neighbours == [{2, 4, 5}, {1, 3, 4, 5}, {1, 2, 4, 5}, {1, 3, 5}, {1, 2, 3}]
    assert not s.formation.mirrored_offsets
    o = s.observer
    assert (o.enabled, o.substeps, o.pi1, o.lambda1, o.pi2, o.lambda2, o.eta, o.rho) == (
        True,
        20,
        1.0,
        2.0,
        2.0,
        1.5,
        0.5,
        2.0,
    )
    assert not o.estimate_without_s0 and not o.literal_sign_law
    d = s.disturbance
    assert (d.model, d.amplitude, d.period, d.noise_scale, d.scalar_rand) == (
        "paper",
        0.2,
        40.0,
        0.1,
        False,
    )
    assert d.wind == (0.0, 0.0, 0.0) and d.gust_std == 0.0
    assert s.schedule.times == (50.0, 100.0, 150.0)
    assert s.schedule.velocities == ((20.0, 0, 0), (0, 20.0, 0), (-20.0, 0, 0), (0, -20.0, 0))
    assert s.initial.position_low == (0.0, -40.0, 0.0)
    assert s.initial.position_high == (40.0, 40.0, 0.0)
    assert s.initial.velocity == (20.0, 0.0, 0.0)
    assert [ob.center for ob in s.avoidance.obstacles] == [(300.0, 0.0), (1050.0, 400.0)]
    assert [ob.radius for ob in s.avoidance.obstacles] == [30.0, 30.0]
    assert s.avoidance.safety_radius(s.avoidance.obstacles[0]) == 40.0  # R_s
    assert 30.0 + s.avoidance.detection_margin == 70.0  # d^o from the centre
    assert s.collision.mode == "none"
    assert has_directed_spanning_tree(h0)


def test_scenarios_are_frozen() -> None:
    s = Scenario()
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.duration = 10.0  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.observer.eta = 1.0  # type: ignore[misc]


# ------------------------------------------------------------------------------------------------
# YAML round trip
# ------------------------------------------------------------------------------------------------


def test_yaml_round_trip_default(tmp_path: Path) -> None:
    path = tmp_path / "paper.yaml"
    save_scenario(Scenario(), path)
    loaded = load_scenario(path)
    assert loaded == Scenario()
    # every field is written out
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    assert set(data) == {f.name for f in dataclasses.fields(Scenario)}
    assert data["observer"]["lambda2"] == 1.5


def test_yaml_round_trip_non_default(tmp_path: Path) -> None:
    s = Scenario(
        name="custom",
        duration=12.0,
        dynamics=DynamicsConfig(dt=0.1, u_max=3.5),
        disturbance=DisturbanceConfig(scalar_rand=True, wind=(0.1, -0.2, 0.0), gust_std=0.05),
        observer=ObserverConfig(substeps=40, lambda2=1.25, estimate_without_s0=True),
        formation=FormationConfig(
            offsets=((0, 0, 0, 0, 0, 0), (1.5, 2, 0, 0, 0, 0), (3, -2, 0, 0, 0, 0)),
            adjacency=((0, 0, 0), (1, 0, 0), (0, 1, 0)),
            mirrored_offsets=True,
        ),
        avoidance=AvoidanceConfig(obstacles=(ObstacleConfig((100.0, 20.0), 5.0),)),
        cost=CostConfig(q=2.0, horizon=3),
        schedule=ScheduleConfig(times=(5.0,), velocities=((1, 2, 3), (4, 5, 6))),
        initial=InitialStateConfig(velocity=(15.0, 1.0, 0.0)),
        collision=CollisionConfig(mode="penalty", penalty=5.0),
    )
    path = tmp_path / "custom.yml"
    save_scenario(s, path)
    loaded = load_scenario(path)
    assert loaded == s
    assert loaded.n_steps == 120
    assert isinstance(loaded.formation.offsets, tuple)
    assert isinstance(loaded.avoidance.obstacles[0], ObstacleConfig)
    assert scenario_from_dict(to_dict(s)) == s


def test_empty_yaml_is_paper(tmp_path: Path) -> None:
    path = tmp_path / "empty.yaml"
    path.write_text("", encoding="utf-8")
    assert load_scenario(path) == Scenario()
    path.write_text("observer:\n  substeps: 40\n", encoding="utf-8")
    assert load_scenario(path) == Scenario(observer=ObserverConfig(substeps=40))


# ------------------------------------------------------------------------------------------------
# unknown keys
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("data", "dotted"),
    [
        ({"durration": 100.0}, "'durration'"),
        ({"observer": {"lamda2": 1.5}}, "'observer.lamda2'"),
        ({"dynamics": {"dt": 0.2, "mass_kg": 3}}, "'dynamics.mass_kg'"),
        (
            {"avoidance": {"obstacles": [{"center": [0, 0], "radius": 3, "hight": 2}]}},
            "'avoidance.obstacles[0].hight'",
        ),
    ],
)
def test_unknown_keys_are_named(data: dict[str, Any], dotted: str) -> None:
    with pytest.raises(ValueError, match="unknown") as info:
        scenario_from_dict(data)
    assert dotted in str(info.value)


def test_unknown_key_in_yaml_file(tmp_path: Path) -> None:
    path = tmp_path / "typo.yaml"
    path.write_text("observer:\n  lamda2: 1.5\n", encoding="utf-8")
    with pytest.raises(ValueError, match=r"observer\.lamda2"):
        load_scenario(path)


# ------------------------------------------------------------------------------------------------
# impossible values: ValueError naming the field
# ------------------------------------------------------------------------------------------------

TWO_PAIRS = ((0, 1, 0, 0), (1, 0, 0, 0), (0, 0, 0, 1), (0, 0, 1, 0))
FOUR_OFFSETS = tuple((float(i), 0.0, 0.0, 0.0, 0.0, 0.0) for i in range(4))

INVALID: list[tuple[str, dict[str, Any], str]] = [
    (
        "non-square adjacency",
        {"formation": {"offsets": FOUR_OFFSETS[:3], "adjacency": ((0, 1, 1), (1, 0), (1, 1, 0))}},
        r"formation\.adjacency'.*square",
    ),
    (
        "adjacency size vs offsets",
        {"formation": {"adjacency": TWO_PAIRS}},
        r"formation\.adjacency'.*4x4.*formation\.offsets has 5",
    ),
    (
        "adjacency entry 2",
        {"formation": {"offsets": FOUR_OFFSETS[:2], "adjacency": ((0, 2), (1, 0))}},
        r"formation\.adjacency'.*0 or 1",
    ),
    (
        "adjacency entry 0.5",
        {"formation": {"offsets": FOUR_OFFSETS[:2], "adjacency": ((0, 1), (1, 0.5))}},
        r"formation\.adjacency\[1\]\[1\]'",
    ),
    (
        "non-zero diagonal",
        {"formation": {"offsets": FOUR_OFFSETS[:2], "adjacency": ((1, 1), (1, 0))}},
        r"formation\.adjacency'.*diagonal",
    ),
    (
        "no spanning tree (two disconnected pairs)",
        {"formation": {"offsets": FOUR_OFFSETS, "adjacency": TWO_PAIRS}},
        r"formation\.adjacency'.*spanning tree",
    ),
    (
        "single UAV",
        {"formation": {"offsets": FOUR_OFFSETS[:1], "adjacency": ((0,),)}},
        r"formation\.offsets'",
    ),
    (
        "offset of 5 components",
        {
            "formation": {
                "offsets": ((0, 0, 0, 0, 0), (1, 0, 0, 0, 0)),
                "adjacency": ((0, 1), (1, 0)),
            }
        },
        r"formation\.offsets'",
    ),
    ("dt = 0", {"dynamics": {"dt": 0.0}}, r"dynamics\.dt'"),
    ("dt < 0", {"dynamics": {"dt": -0.2}}, r"dynamics\.dt'"),
    ("dt nan", {"dynamics": {"dt": math.nan}}, r"dynamics\.dt'"),
    ("duration not a multiple of dt", {"duration": 200.1}, r"'duration'.*whole number"),
    ("duration shorter than a step", {"duration": 0.1}, r"'duration'"),
    ("duration 0", {"duration": 0.0}, r"'duration'"),
    ("lambda2 = 1", {"observer": {"lambda2": 1.0}}, r"observer\.lambda2'.*\(1, 2\)"),
    ("lambda2 = 2", {"observer": {"lambda2": 2.0, "lambda1": 3.0}}, r"observer\.lambda2'"),
    ("lambda2 = 2.5", {"observer": {"lambda2": 2.5, "lambda1": 3.0}}, r"observer\.lambda2'"),
    ("lambda1 = lambda2", {"observer": {"lambda1": 1.5}}, r"observer\.lambda1'.*> lambda2"),
    ("lambda1 < lambda2", {"observer": {"lambda1": 1.2}}, r"observer\.lambda1'"),
    ("substeps = 0", {"observer": {"substeps": 0}}, r"observer\.substeps'"),
    ("substeps float", {"observer": {"substeps": 2.5}}, r"observer\.substeps'.*integer"),
    ("eta = 0", {"observer": {"eta": 0.0}}, r"observer\.eta'"),
    ("negative q", {"cost": {"q": -1.0}}, r"cost\.q'"),
    ("negative r", {"cost": {"r": -0.1}}, r"cost\.r'"),
    ("negative m", {"cost": {"m": -2.0}}, r"cost\.m'"),
    ("negative n", {"cost": {"n": -10.0}}, r"cost\.n'"),
    ("horizon 0", {"cost": {"horizon": 0}}, r"cost\.horizon'"),
    ("negative separation", {"cost": {"separation": -1.0}}, r"cost\.separation'.*>= 0"),
    (
        "negative separation distance",
        {"cost": {"separation_distance": -8.0}},
        r"cost\.separation_distance'.*>= 0",
    ),
    ("nan separation", {"cost": {"separation": float("nan")}}, r"cost\.separation'.*finite"),
    (
        "overlapping obstacles",
        {"avoidance": {"obstacles": [{"center": [0, 0]}, {"center": [100, 0]}]}},
        r"avoidance\.obstacles'.*overlap",
    ),
    (
        "negative radius",
        {"avoidance": {"obstacles": [{"center": [0, 0], "radius": -1}]}},
        r"avoidance\.obstacles\.radius'",
    ),
    (
        "detection inside safety",
        {"avoidance": {"safety_margin": 50.0, "detection_margin": 40.0}},
        r"avoidance\.detection_margin'",
    ),
    (
        "schedule times not increasing",
        {"schedule": {"times": [50.0, 40.0, 150.0]}},
        r"schedule\.times'.*increasing",
    ),
    ("schedule times equal", {"schedule": {"times": [50.0, 50.0, 150.0]}}, r"schedule\.times'"),
    (
        "schedule velocities count",
        {"schedule": {"times": [50.0, 100.0]}},
        r"schedule\.velocities'.*3",
    ),
    (
        "position_low > position_high",
        {"initial": {"position_low": [0, 50, 0], "position_high": [40, 40, 0]}},
        r"initial\.position_(low|high)'",
    ),
    ("unknown collision mode", {"collision": {"mode": "explode"}}, r"collision\.mode'.*explode"),
    (
        "negative obstacle distance",
        {"collision": {"obstacle_distance": -1.0}},
        r"collision\.obstacle_distance'",
    ),
    ("unknown disturbance model", {"disturbance": {"model": "dryden"}}, r"disturbance\.model'"),
    ("wind with 2 components", {"disturbance": {"wind": [0.0, 1.0]}}, r"disturbance\.wind'"),
    ("string for a number", {"dynamics": {"dt": "0.2"}}, r"dynamics\.dt'.*number"),
    ("bool for a number", {"cost": {"q": True}}, r"cost\.q'"),
    ("number for a bool", {"observer": {"enabled": 1}}, r"observer\.enabled'"),
    ("number for a string", {"collision": {"mode": 3}}, r"collision\.mode'"),
    ("scalar for a section", {"observer": 3}, r"'observer'"),
    ("scalar for a list", {"schedule": {"times": 50.0}}, r"schedule\.times'"),
    ("reference speed", {"avoidance": {"reference_speed": "fast"}}, r"avoidance\.reference_speed'"),
]


@pytest.mark.parametrize(("case", "data", "pattern"), INVALID, ids=[c[0] for c in INVALID])
def test_invalid_values_name_the_field(case: str, data: dict[str, Any], pattern: str) -> None:
    with pytest.raises(ValueError, match=pattern) as info:
        scenario_from_dict(data)
    assert "invalid scenario field" in str(info.value), case


def test_direct_construction_validates_too() -> None:
    with pytest.raises(ValueError, match=r"dynamics\.dt'"):
        DynamicsConfig(dt=0.0)
    with pytest.raises(ValueError, match=r"observer\.substeps'"):
        ObserverConfig(substeps=0)
    with pytest.raises(ValueError, match=r"observer\.lambda2'"):
        ObserverConfig(lambda2=1.0)
    with pytest.raises(ValueError, match=r"'duration'"):
        Scenario(duration=1.0, dynamics=DynamicsConfig(dt=0.3))
    with pytest.raises(ValueError, match=r"formation\.adjacency'"):
        FormationConfig(offsets=FOUR_OFFSETS, adjacency=TWO_PAIRS)
    with pytest.raises(ValueError, match=r"collision\.mode'"):
        CollisionConfig(mode="Terminate")


def test_boundary_values_are_accepted() -> None:
    # obstacles exactly touching detection circles, zero weights, lambda2 near the ends
    ok = AvoidanceConfig(obstacles=(ObstacleConfig((0.0, 0.0)), ObstacleConfig((140.0, 0.0))))
    assert len(ok.obstacles) == 2
    assert CostConfig(q=0.0, r=0.0, m=0.0, n=0.0).q == 0.0
    assert CostConfig(separation=0.0, separation_distance=0.0).separation == 0.0  # paper's J_i
    assert ObserverConfig(lambda2=1.01, lambda1=1.02).lambda2 == 1.01
    assert ObserverConfig(lambda2=1.99, lambda1=2.0).lambda2 == 1.99
    assert Scenario(duration=0.2).n_steps == 1
    assert Scenario(duration=3.0, dynamics=DynamicsConfig(dt=0.1)).n_steps == 30
    assert InitialStateConfig(position_low=(1, 1, 1), position_high=(1, 1, 1)).velocity
    # an int in YAML for a float field is accepted and stored as float
    s = scenario_from_dict({"duration": 100, "dynamics": {"dt": 1}})
    assert s.n_steps == 100 and isinstance(s.dynamics.dt, float)


# ------------------------------------------------------------------------------------------------
# spanning tree
# ------------------------------------------------------------------------------------------------


def chain(n: int) -> np.ndarray:
    """Directed chain 0 -> 1 -> ... -> n-1 (i receives from i-1)."""
    a = np.zeros((n, n), dtype=int)
    for i in range(1, n):
        a[i, i - 1] = 1
    return a


@pytest.mark.parametrize("n", list(range(2, 18)))
def test_directed_chain_has_spanning_tree(n: int) -> None:
    # long chains check that enough hops are explored (path length n - 1)
    assert has_directed_spanning_tree(chain(n))
    assert has_directed_spanning_tree(chain(n)[::-1, ::-1])  # root at the other end
    broken = chain(n)
    broken[n - 1, n - 2] = 0
    broken[n - 2, n - 1] = 1  # last edge reversed: two sinks-from-different-roots
    assert has_directed_spanning_tree(broken) == (n == 2)


def test_spanning_tree_hand_graphs() -> None:
    # 0 -> 1 <- 2 -> 3 : the middle edge reversed; 0 reaches {0,1}, 2 reaches {1,2,3}
    a = np.zeros((4, 4), dtype=int)
    a[1, 0] = 1
    a[1, 2] = 1
    a[3, 2] = 1
    assert not has_directed_spanning_tree(a)
    a[2, 1] = 1  # add 1 -> 2: now 0 reaches everything
    assert has_directed_spanning_tree(a)
    # two disconnected pairs
    assert not has_directed_spanning_tree(np.array(TWO_PAIRS))
    # a star whose centre only sends
    star = np.zeros((5, 5), dtype=int)
    star[1:, 0] = 1
    assert has_directed_spanning_tree(star)
    assert not has_directed_spanning_tree(star.T)  # centre only receives
    # no edges at all
    assert not has_directed_spanning_tree(np.zeros((3, 3), dtype=int))
    # the paper graph is strongly connected: every node is a root
    h0 = np.array(Scenario().formation.adjacency)
    for i in range(5):
        reach = {i}
        for _ in range(5):
            reach |= {r for r in range(5) for j in reach if h0[r, j]}
        assert reach == set(range(5))


def test_spanning_tree_edge_direction() -> None:
    """adjacency[i, j] = 1 means i receives from j, i.e. an edge j -> i."""
    # 1 <- 0 and 2 <- 0: root 0 sends to both
    a = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 0]])
    assert has_directed_spanning_tree(a)
    # 0 <- 1 and 0 <- 2: 0 receives from both, nobody reaches both 1 and 2
    assert not has_directed_spanning_tree(a.T)


# ------------------------------------------------------------------------------------------------
# overrides and scenario resolution
# ------------------------------------------------------------------------------------------------


def test_with_overrides_forms() -> None:
    base = Scenario()
    nested = with_overrides(base, {"observer": {"enabled": False, "substeps": 40}})
    dotted = with_overrides(base, {"observer.enabled": False, "observer.substeps": 40})
    dunder = with_overrides(base, {"observer__enabled": False, "observer__substeps": 40})
    expected = dataclasses.replace(
        base, observer=dataclasses.replace(base.observer, enabled=False, substeps=40)
    )
    assert nested == dotted == dunder == expected
    assert base == Scenario()  # the original is untouched
    # deeper and mixed keys
    s = with_overrides(
        base,
        {
            "duration": 20.0,
            "cost.q": 2.0,
            "disturbance__wind": (0.1, 0.0, 0.0),
            "initial": {"velocity": [15, 0, 0]},
        },
    )
    assert s.duration == 20.0 and s.n_steps == 100
    assert s.cost.q == 2.0 and s.cost.r == 5.0
    assert s.disturbance.wind == (0.1, 0.0, 0.0)
    assert s.initial.velocity == (15.0, 0.0, 0.0)
    assert s.observer == base.observer
    # a partial override keeps the other non-default fields of the base (a merge, not a reset)
    tuned = with_overrides(base, {"observer.eta": 0.7, "cost.horizon": 3, "name": "tuned"})
    for patch in (
        {"observer": {"enabled": False}},
        {"observer.enabled": False},
        {"observer__enabled": False},
    ):
        out = with_overrides(tuned, patch)
        assert out.observer == dataclasses.replace(tuned.observer, enabled=False)
        assert out.observer.eta == 0.7 and out.cost.horizon == 3 and out.name == "tuned"
    # a whole section as a config object
    s2 = with_overrides(base, {"observer": ObserverConfig(eta=0.7)})
    assert s2.observer == ObserverConfig(eta=0.7)
    # obstacles as objects
    s3 = with_overrides(base, {"avoidance.obstacles": (ObstacleConfig((95.0, 5.0), 10.0),)})
    assert s3.avoidance.obstacles == (ObstacleConfig((95.0, 5.0), 10.0),)


def test_with_overrides_rejects_unknown_and_invalid() -> None:
    with pytest.raises(ValueError, match=r"observer\.lamda2"):
        with_overrides(Scenario(), {"observer.lamda2": 1.5})
    with pytest.raises(ValueError, match=r"observer\.lamda2"):
        with_overrides(Scenario(), {"observer__lamda2": 1.5})
    with pytest.raises(ValueError, match=r"'nonsense'"):
        with_overrides(Scenario(), {"nonsense": 1})
    with pytest.raises(ValueError, match=r"observer\.lambda2'"):
        with_overrides(Scenario(), {"observer.lambda2": 2.5})
    with pytest.raises(ValueError, match=r"'duration'"):
        with_overrides(Scenario(), {"duration": 0.3})


def test_resolve_scenario(tmp_path: Path) -> None:
    assert "paper" in SCENARIOS
    assert resolve_scenario() == Scenario()
    assert resolve_scenario("paper") == Scenario()
    custom = with_overrides(Scenario(), {"name": "short", "duration": 10.0})
    assert resolve_scenario(custom) is custom
    path = tmp_path / "short.yaml"
    save_scenario(custom, path)
    assert resolve_scenario(path) == custom
    assert resolve_scenario(str(path)) == custom
    assert resolve_scenario({"duration": 10.0, "name": "short"}) == custom
    with pytest.raises(ValueError, match=r"'durration'"):
        resolve_scenario({"durration": 10.0})
    with pytest.raises(ValueError, match=r"scenario file not found: '.*missing\.yaml'"):
        resolve_scenario(tmp_path / "missing.yaml")
    with pytest.raises(TypeError, match=r"scenario must be a registered name .* got 42 \(int\)"):
        resolve_scenario(42)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"unknown scenario 'papper'"):
        resolve_scenario("papper")
    with pytest.raises(ValueError, match="scenario file not found"):
        resolve_scenario(tmp_path / "missing.yaml")
    txt = tmp_path / "short.txt"
    txt.write_text("duration: 10.0\n", encoding="utf-8")
    with pytest.raises(ValueError, match="unknown scenario"):
        resolve_scenario(txt)


# ------------------------------------------------------------------------------------------------
# scene section (uav_formation_env.scenes; more in tests/test_scenes.py)
# ------------------------------------------------------------------------------------------------


def test_optional_sections_convert_or_stay_none() -> None:
    from uav_formation_env.config import ObstacleFieldConfig, SceneConfig

    assert scenario_from_dict({"scene": None}).scene is None
    s = scenario_from_dict(
        {"scene": {"n_uav": [3, 4], "shapes": ["v", "grid"], "obstacles": {"count": [0, 2]}}}
    )
    # the mapping became its dataclass, the lists tuples of the hinted types
    assert s.scene == SceneConfig(
        n_uav=(3, 4), shapes=("v", "grid"), obstacles=ObstacleFieldConfig(count=(0, 2))
    )
    assert isinstance(s.scene.obstacles.radius[0], float)
    with pytest.raises(ValueError, match=r"'scene\.spacing'.*expected 2 entries"):
        scenario_from_dict({"scene": {"spacing": [1.0, 2.0, 3.0]}})
    with pytest.raises(ValueError, match=r"'scene\.obstacles'.*expected a mapping"):
        scenario_from_dict({"scene": {"obstacles": 3}})


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_registered_scenarios_build_and_round_trip(name: str, tmp_path: Path) -> None:
    scenario = resolve_scenario(name)
    path = tmp_path / f"{name}.yaml"
    save_scenario(scenario, path)
    assert load_scenario(path) == scenario


def test_sparse_graph_edge_list_in_yaml(tmp_path: Path) -> None:
    # receiver, sender pairs: UAV 0 leads, 1 and 2 receive from it, 2 also from 1
    offsets = [[0.0] * 6, [-10.0, 10.0, 0, 0, 0, 0], [-10.0, -10.0, 0, 0, 0, 0]]
    edges = {"edges": [[1, 0], [2, 0], [2, 1]]}
    sparse = scenario_from_dict({"formation": {"offsets": offsets, "adjacency": edges}})
    assert sparse.formation.adjacency == ((0, 0, 0), (1, 0, 0), (1, 1, 0))
    with pytest.raises(ValueError, match=r"'formation\.adjacency\.edgs'"):
        scenario_from_dict({"formation": {"offsets": offsets, "adjacency": {"edgs": []}}})
    with pytest.raises(ValueError, match=r"'formation\.adjacency\.edges\[1\]'.*0\.\.2.*\[2, 3\]"):
        bad = {"edges": [[1, 0], [2, 3]]}
        scenario_from_dict({"formation": {"offsets": offsets, "adjacency": bad}})
    with pytest.raises(ValueError, match=r"formation\.adjacency.*spanning tree"):
        scenario_from_dict({"formation": {"offsets": offsets, "adjacency": {"edges": [[1, 0]]}}})


def test_large_formations_are_saved_as_edge_lists(tmp_path: Path) -> None:
    from uav_formation_env.config_io import SPARSE_GRAPH_MIN_UAVS
    from uav_formation_env.scenarios import swarm_scenario

    large, small = swarm_scenario(SPARSE_GRAPH_MIN_UAVS), swarm_scenario(SPARSE_GRAPH_MIN_UAVS - 1)
    for scenario, sparse in ((large, True), (small, False)):
        path = tmp_path / f"{scenario.n_uav}.yaml"
        save_scenario(scenario, path)
        stored = yaml.safe_load(path.read_text())["formation"]["adjacency"]
        assert isinstance(stored, dict) is sparse
        assert load_scenario(path) == scenario
    stored = yaml.safe_load((tmp_path / f"{large.n_uav}.yaml").read_text())
    edges = stored["formation"]["adjacency"]["edges"]
    assert len(edges) == int(np.asarray(large.formation.adjacency).sum())


@pytest.mark.parametrize("n_uav", [100, 900, 1000])
def test_swarm_obstacles_keep_their_safety_circles_off_the_start_box(n_uav: int) -> None:
    from uav_formation_env.scenarios import swarm_scenario

    scenario = swarm_scenario(n_uav)  # validated: no cylinder reaches into the start box
    low, high = scenario.initial.position_low, scenario.initial.position_high
    for obstacle in scenario.avoidance.obstacles:
        (x, y), reach = obstacle.center, scenario.avoidance.safety_radius(obstacle)
        gap = np.hypot(max(low[0] - x, 0.0, x - high[0]), max(low[1] - y, 0.0, y - high[1]))
        assert gap >= reach - 1e-9
    # below 1000 the radius is the paper's scaled to the formation's width, as before
    assert swarm_scenario(900).avoidance.obstacles[0].radius == 108.75
