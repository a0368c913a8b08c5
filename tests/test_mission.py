"""Mission metrics on hand-built trajectories, and the reference policy's mission on the paper."""

from __future__ import annotations

import numpy as np
import pytest

from uav_formation_env.config_io import with_overrides
from uav_formation_env.core.reference import preset_displacement
from uav_formation_env.evaluation import (
    make_policy,
    mean_ci95,
    mission_metrics,
    mission_summary,
    run_episodes,
    summarise,
)
from uav_formation_env.scenarios import make_scenario

DT = 0.2


def straight_scenario(obstacles=(), duration: float = 40.0, **overrides):
    """Preset route: 20 m/s along +x for the whole episode, optional obstacles."""
    scenario = make_scenario(obstacles="none", duration=duration)
    patch = {
        "schedule": {"times": [], "velocities": [[20.0, 0.0, 0.0]]},
        "avoidance": {"obstacles": [{"center": list(c), "radius": r} for c, r in obstacles]},
        **overrides,
    }
    return with_overrides(scenario, patch)


def flight(scenario, offset=(0.0, 0.0), n_uav: int = 5, spacing: float = 30.0):
    """UAVs in a line abreast (``spacing`` apart in y) flying the preset route exactly, shifted
    by ``offset`` (x, y) [m] from t > 0 on: (t, z (T+1, 1, N, 6), no collisions, separation)."""
    t = np.arange(scenario.n_steps + 1) * DT
    route = preset_displacement(scenario.schedule, t)  # (T+1, 3)
    z = np.zeros((len(t), 1, n_uav, 6))
    slots = np.zeros((n_uav, 3))
    slots[:, 1] = spacing * (np.arange(n_uav) - (n_uav - 1) / 2)
    z[..., :3] = route[:, None, None, :] + slots
    z[1:, ..., 0] += offset[0]
    z[1:, ..., 1] += offset[1]
    z[..., 3:] = 20.0 * np.array([1.0, 0.0, 0.0])
    collision = np.zeros((len(t) - 1, 1, n_uav), dtype=bool)
    separation = np.full((len(t), 1, n_uav), spacing)
    return t, z, collision, separation


def test_preset_displacement_is_the_integral_of_the_schedule() -> None:
    scenario = make_scenario()  # paper schedule: +x until 50 s, +y until 100 s, -x, -y
    d = preset_displacement(scenario.schedule, np.array([0.0, 25.0, 50.0, 75.0, 150.0, 175.0]))
    expected = [[0, 0, 0], [500, 0, 0], [1000, 0, 0], [1000, 500, 0], [0, 1000, 0], [0, 500, 0]]
    np.testing.assert_allclose(d, expected, atol=1e-9)


def test_straight_flight_on_the_route_has_zero_error() -> None:
    scenario = straight_scenario()
    m = mission_metrics(scenario, *flight(scenario))
    assert m.route_error_rms[0] == pytest.approx(0.0, abs=1e-9)
    assert m.route_error_max[0] == pytest.approx(0.0, abs=1e-9)
    assert m.velocity_rmse[0] == pytest.approx(0.0, abs=1e-12)
    assert m.completed.tolist() == [True]


def test_constant_lateral_offset_of_50_m_is_50_m() -> None:
    scenario = straight_scenario()
    m = mission_metrics(scenario, *flight(scenario, offset=(0.0, 50.0)))
    assert m.route_error_max[0] == pytest.approx(50.0)
    # t = 0 is on the route by definition, the T later samples are 50 m off
    steps = scenario.n_steps
    assert m.route_error_rms[0] == pytest.approx(50.0 * np.sqrt(steps / (steps + 1)))
    assert m.completed.tolist() == [True]  # 50 m <= 100 m
    far = mission_metrics(scenario, *flight(scenario, offset=(0.0, 150.0)))
    assert far.completed.tolist() == [False]
    assert far.failures() == [["route error max 150 m > 100 m"]]
    tighter = with_overrides(scenario, {"mission": {"max_route_error": 40.0}})
    assert mission_metrics(tighter, *flight(scenario, offset=(0.0, 50.0))).completed[0] == False  # noqa: E712


def test_obstacle_skirted_at_100_m_is_not_met_and_fails_the_mission() -> None:
    # d^o = 30 + 40 = 70 m. The route passes through the obstacle; the UAVs (line abreast, 30 m
    # apart: outermost 60 m from the centroid) fly 160 m to its side, so the nearest UAV passes
    # 100 m from its centre.
    scenario = straight_scenario(obstacles=[((400.0, 0.0), 30.0)])
    m = mission_metrics(scenario, *flight(scenario, offset=(0.0, 160.0)))
    assert m.obstacle_required.tolist() == [[True]]
    assert m.obstacle_met.tolist() == [[False]]
    assert m.obstacle_closest[0, 0] == pytest.approx(100.0)
    assert np.isnan(m.obstacle_time_met[0, 0])
    assert m.completed.tolist() == [False]
    assert "O1 not met (closest 100 m from its centre)" in m.failures()[0]


def test_obstacle_met_on_the_route_and_its_time() -> None:
    scenario = straight_scenario(obstacles=[((400.0, 0.0), 30.0)])
    m = mission_metrics(scenario, *flight(scenario))
    assert m.obstacle_met.tolist() == [[True]]
    # the centre UAV (y = 0) comes within 70 m of x = 400 at x = 330: t = 16.5 s, sampled at 16.6
    assert m.obstacle_time_met[0, 0] == pytest.approx(16.6)
    assert m.obstacle_closest[0, 0] == pytest.approx(0.0)


def test_obstacle_off_the_route_is_not_required() -> None:
    scenario = straight_scenario(obstacles=[((400.0, 300.0), 30.0)])
    m = mission_metrics(scenario, *flight(scenario))
    assert m.obstacle_required.tolist() == [[False]]
    assert m.obstacle_met.tolist() == [[False]]
    assert m.completed.tolist() == [True]


def test_collisions_and_separation_count_after_t0_only() -> None:
    scenario = straight_scenario()
    t, z, collision, separation = flight(scenario)
    separation[0] = 0.5  # the layout at t = 0 is not counted
    separation[7, 0, 2] = 3.0
    m = mission_metrics(scenario, t, z, collision, separation)
    assert m.min_separation[0] == pytest.approx(3.0)
    assert m.min_separation_time[0] == pytest.approx(7 * DT)
    assert m.completed.tolist() == [True]
    collision[10, 0, 3] = collision[12, 0, 1] = True
    m = mission_metrics(scenario, t, z, collision, separation)
    assert m.collisions.tolist() == [2]
    assert m.first_collision_time[0] == pytest.approx(11 * DT)  # collision[k]: after step k+1
    assert m.completed.tolist() == [False]


def test_mean_ci95_matches_student_t() -> None:
    mean, half = mean_ci95(np.array([1.0, 2.0, 3.0, 4.0]))
    assert mean == 2.5
    assert half == pytest.approx(3.182 * np.std([1, 2, 3, 4], ddof=1) / 2)
    assert mean_ci95(np.array([5.0])) == (5.0, 0.0)
    values = np.random.default_rng(0).normal(size=200)
    scipy_stats = pytest.importorskip("scipy.stats")
    expected = scipy_stats.t.ppf(0.975, 199) * values.std(ddof=1) / np.sqrt(200)
    assert mean_ci95(values)[1] == pytest.approx(expected, rel=1e-3)


def test_summary_lists_failures_by_seed() -> None:
    scenario = straight_scenario(obstacles=[((400.0, 0.0), 30.0)])
    good = flight(scenario)
    bad = flight(scenario, offset=(0.0, 160.0))
    both = [np.concatenate([g, b], axis=1) if g.ndim > 1 else g for g, b in zip(good, bad)]
    summary = mission_summary(mission_metrics(scenario, *both), seeds=[3, 4])
    assert summary["completed"] == 1 and summary["completion_rate"] == 0.5
    assert list(summary["failures"]) == ["4"]
    assert summary["obstacles"]["O1"]["met_per_seed"] == [True, False]


def test_reference_policy_flies_the_paper_mission() -> None:
    """LFPIO with the observer completes the paper's mission: both obstacles met, no collision,
    route error within 100 m (two seeds, the whole 200 s)."""
    scenario = make_scenario()
    batch = run_episodes(scenario, make_policy("lfpio", scenario), [0, 1])
    mission = summarise(batch)["mission"]
    assert mission["completed"] == 2, mission["failures"]
    assert all(o["met"] == 2 for o in mission["obstacles"].values())
    assert mission["collisions_after_start"] == 0
    assert mission["route_error_max_m"] < 100.0
