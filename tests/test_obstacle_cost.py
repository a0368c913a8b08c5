"""The obstacle clearance term of J_i (docs/deviations.md §8): hand-computed values, the stage
and horizon sums, the fast population evaluation and its screen, the exact solver's refinement,
the decoded full-layout obstacle, and the term's effect on a UAV heading into an obstacle."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from uav_formation_env.config import CostConfig
from uav_formation_env.config_io import paper_scenario, scenario_from_dict
from uav_formation_env.core.cost import horizon_cost, prepare_horizon_cost, stage_cost
from uav_formation_env.core.dynamics import rollout
from uav_formation_env.core.observation import build_observations, decode_observations
from uav_formation_env.policies.best_response import best_response, identification_evaluations
from uav_formation_env.policies.broadcast import horizon_problems
from uav_formation_env.sim import FormationSim

DT = 0.2
ONE = np.zeros((1, 1, 1, 6))  # no neighbours' trajectories matter: one UAV, no edges
NO_EDGES = np.zeros((1, 1, 1))
OFFSET = np.zeros((1, 6))


def one_uav_cost(weights: CostConfig, centre, clearance, velocity=(10.0, 0.0, 0.0)):
    """UAV at the origin with ``velocity``; one sensed obstacle; H from ``weights``."""
    z0 = np.array([[[0.0, 0.0, 0.0, *velocity]]])
    h = weights.horizon
    reference = np.broadcast_to(np.asarray(velocity), (1, 1, h + 1, 3))
    return prepare_horizon_cost(
        z0,
        np.broadcast_to(z0[:, :, None], (1, 1, h + 1, 6)),
        reference,
        NO_EDGES,
        OFFSET,
        weights,
        DT,
        obstacle_centre=np.asarray(centre, dtype=float).reshape(1, 1, -1, 2),
        obstacle_clearance=np.asarray(clearance, dtype=float).reshape(1, 1, -1),
    )


def test_stage_obstacle_term_by_hand() -> None:
    """o max(0, c_o - surface)²: 3 x 5², 0 outside the margin, 3 x 12² inside the obstacle, 0
    without obstacles (+inf); the other terms are unchanged by it."""
    w = CostConfig(obstacle=3.0, obstacle_margin=10.0, separation=0.0)
    z = np.zeros((1, 4, 6))
    z[0, :, 0] = [0.0, 100.0, 200.0, 300.0]  # far apart
    surface = np.array([[5.0, 12.0, -2.0, np.inf]])
    args = (z, np.zeros((1, 4, 3)), np.zeros((1, 4, 3)), np.zeros((1, 4, 4)), np.zeros((4, 6)))
    terms = stage_cost(*args, w, obstacle_surface=surface)
    np.testing.assert_array_equal(terms.obstacle, [[75.0, 0.0, 432.0, 0.0]])
    np.testing.assert_array_equal(terms.total, terms.obstacle)
    off = stage_cost(*args, replace(w, obstacle=0.0), obstacle_surface=surface)
    np.testing.assert_array_equal(off.obstacle, 0.0)
    np.testing.assert_array_equal(stage_cost(*args, w).obstacle, 0.0)  # no obstacle given


def test_horizon_obstacle_term_by_hand_with_lookahead() -> None:
    """H = 1, L = 3: the UAV at the origin at 10 m/s along x, an obstacle centre 12 m ahead with
    clearance 15 m. Zero input: points x = 0, 2 (horizon) and 4, 6, 8 (free continuation), gaps
    3, 5, 7, 9, 11. Input -5 m/s² along x: x(1) = 2 - 0.1 = 1.9, v(1) = 9, continuation 3.7,
    5.5, 7.3; gaps 3, 4.9, 6.7, 8.5, 10.3."""
    w = CostConfig(horizon=1, obstacle=2.0, obstacle_lookahead=3, separation=0.0)
    cost = one_uav_cost(w, (12.0, 0.0), 15.0)
    candidates = np.array([0.0, 0.0, 0.0, -5.0, 0.0, 0.0]).reshape(1, 1, 2, 1, 3)
    got = cost.terms(candidates).obstacle[0, 0]
    expected = 2.0 * np.array([9 + 25 + 49 + 81 + 121, 3**2 + 4.9**2 + 6.7**2 + 8.5**2 + 10.3**2])
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    # without the lookahead only the horizon's two points count
    short = one_uav_cost(replace(w, obstacle_lookahead=0), (12.0, 0.0), 15.0)
    np.testing.assert_allclose(
        short.terms(candidates).obstacle[0, 0], 2.0 * np.array([9 + 25, 9 + 4.9**2]), rtol=1e-12
    )
    # horizontal: a height difference changes nothing; an absent slot (clearance 0) counts 0
    high = one_uav_cost(w, [(12.0, 0.0), (1.0, 1.0)], [15.0, 0.0])
    np.testing.assert_allclose(high.terms(candidates).obstacle[0, 0], expected, rtol=1e-12)


def test_horizon_obstacle_term_is_the_sum_of_stage_terms() -> None:
    """One definition: without the lookahead the horizon term of a flown candidate is the sum of
    the stage terms at its predicted states (k = 0..H)."""
    rng = np.random.default_rng(5)
    w = CostConfig(obstacle=4.0, obstacle_margin=8.0, separation=0.0)
    z0 = np.concatenate((rng.normal(0, 5, (2, 3, 3)), rng.normal(0, 15, (2, 3, 3))), axis=-1)
    centre = rng.normal(0, 10, (2, 3, 1, 2)) + 15.0
    radius = rng.uniform(5, 15, (2, 3, 1))
    cand = rng.uniform(-5, 5, (2, 3, 1, 5, 3))
    traj = rollout(z0[:, :, None], cand, DT)[:, :, 0]  # (B, N, H+1, 6)
    adj = np.zeros((2, 3, 3))
    ref = np.zeros((2, 3, 6, 3))
    hor = horizon_cost(
        cand, z0, traj, ref, adj, np.zeros((3, 6)), w, DT,
        obstacle_centre=centre, obstacle_clearance=radius + w.obstacle_margin,
    )  # fmt: skip
    surface = np.linalg.norm(traj[..., :2] - centre, axis=-1) - radius  # (B, N, H+1)
    stages = sum(
        stage_cost(
            traj[:, :, k], cand[:, :, 0, 0], ref[:, :, k], adj, np.zeros((3, 6)), w,
            obstacle_surface=surface[:, :, k],
        ).obstacle
        for k in range(6)
    )  # fmt: skip
    assert stages.max() > 0 and (stages == 0).any()
    np.testing.assert_allclose(hor.obstacle[..., 0], stages, rtol=1e-12)


def test_population_cost_with_obstacles_equals_the_direct_cost() -> None:
    """The quadratic form plus the screened obstacle term equals the direct J_i in the box; the
    screen keeps the pairs that can be active and drops the far ones."""
    rng = np.random.default_rng(7)
    b, n, h = 2, 4, 5
    w = CostConfig(obstacle=50.0, obstacle_lookahead=10)
    z0 = np.concatenate((rng.normal(0, 30, (b, n, 3)), rng.normal(0, 10, (b, n, 3))), axis=-1)
    z0[..., 3] += 20.0
    centre = z0[:, :, None, :2] + np.array([30.0, 0.0]) + rng.normal(0, 5, (b, n, 2, 2))
    centre[0, 1] += 500.0  # copy 0, UAV 1: both obstacles out of reach
    clearance = rng.uniform(15, 40, (b, n, 2))
    clearance[1, 2, 1] = 0.0  # an absent slot
    neighbours = rollout(z0[:, :, None], rng.uniform(-5, 5, (b, n, 1, h, 3)), DT)[:, :, 0]
    adj = (rng.random((b, n, n)) < 0.5) * (1 - np.eye(n))
    ref = rng.normal(0, 20, (b, n, h + 1, 3))
    prepared = prepare_horizon_cost(
        z0, neighbours, ref, adj, np.zeros((n, 6)), w, DT,
        obstacle_centre=centre, obstacle_clearance=clearance,
    )  # fmt: skip
    half = rng.uniform(1.0, 5.0, (b, n, 3))
    cand = rng.uniform(-1, 1, (b, n, 30, h, 3)) * half[:, :, None, None, :]
    direct = prepared.terms(cand)
    assert direct.obstacle.max() > 100.0 and (direct.obstacle == 0).any()
    quad = prepared.quadratic(half_width=half)
    np.testing.assert_allclose(quad.total(cand), direct.total, rtol=1e-10, atol=1e-8)
    part = prepared.obstacle_part(half)
    everything = prepared.obstacle_part()
    assert part.others.shape[0] < everything.others.shape[0] == b * n * 2 - 1
    assert 1 not in part.rows  # copy 0, UAV 1: nothing within reach
    index = np.array([5, 0, 3])
    np.testing.assert_allclose(
        quad.take(index).total(cand.reshape(b * n, 30, h, 3)[index][None])[0],
        direct.total.reshape(b * n, 30)[index],
        rtol=1e-10,
    )
    # off: the same J_i as without any obstacle arrays
    off = replace(w, obstacle=0.0)
    plain = prepare_horizon_cost(z0, neighbours, ref, adj, np.zeros((n, 6)), off, DT)
    with_arrays = prepare_horizon_cost(
        z0, neighbours, ref, adj, np.zeros((n, 6)), off, DT,
        obstacle_centre=centre, obstacle_clearance=clearance,
    )  # fmt: skip
    np.testing.assert_array_equal(with_arrays.terms(cand).total, plain.terms(cand).total)
    assert with_arrays.quadratic(half).obstacle is None


def test_obstacle_screen_is_exact_at_the_edge_of_the_box() -> None:
    """A UAV at rest, box ±5 m/s²: full thrust along x for 1 s reaches x = 2.5 m. An obstacle
    whose clearance circle (15 m) starts at x = 1.5 m is active for that candidate only; the
    screen must keep it, and the fast evaluation must give the direct term (w (1² + 0.1²): x = 2.5
    and 1.6 m at k = 5 and 4)."""
    w = CostConfig(obstacle=3.0, separation=0.0)
    cost = one_uav_cost(w, (16.5, 0.0), 15.0, velocity=(0.0, 0.0, 0.0))
    half = np.full((1, 1, 3), 5.0)
    full = np.zeros((1, 1, 2, 5, 3))
    full[0, 0, 1, :, 0] = 5.0  # candidate 1: full thrust along x
    direct = cost.terms(full).obstacle[0, 0]
    assert direct[0] == 0.0 and direct[1] == pytest.approx(3.0 * 1.01, rel=1e-9)
    np.testing.assert_allclose(cost.quadratic(half).total(full), cost.terms(full).total)
    assert cost.obstacle_part(half).rows.shape == (1,)
    # the screen bounds the reach per axis (||(2.5, 2.5)|| = 3.54 m): a centre 18.6 m away,
    # 15.06 m beyond it, is dropped; at 18.5 m it is kept (conservatively: never active)
    far = one_uav_cost(w, (18.6, 0.0), 15.0, velocity=(0.0, 0.0, 0.0))
    assert far.obstacle_part(half).rows.shape == (0,)
    kept = one_uav_cost(w, (18.5, 0.0), 15.0, velocity=(0.0, 0.0, 0.0))
    assert kept.obstacle_part(half).rows.shape == (1,)


def heading_into_obstacle(weights: CostConfig):
    """The paper's V in formation at its preset 20 m/s with one obstacle (radius 20 m) 45 m ahead
    of UAV 0, and the given cost weights: the decoded observations and every UAV's horizon
    problem."""
    scenario = replace(paper_scenario(), cost=weights)
    sim = FormationSim(scenario)
    sim.reset(seed=0)
    r = sim.last
    z = np.zeros_like(r.z)
    z[0] = sim.offsets + np.array([500.0, 0.0, 0.0, 20.0, 0.0, 0.0])  # in formation at 20 m/s
    centres = z[0, 0, :2][None] + np.array([[65.0, 0.0]])  # surface 45 m ahead of UAV 0
    obs = build_observations(
        z, r.reference_velocity, r.estimate, r.adjacency, r.avoiding, r.t / scenario.duration,
        sim.offsets, centres, np.array([20.0]), r.min_separation,
    )  # fmt: skip
    decoded = decode_observations(obs, 5)
    return decoded, horizon_problems(decoded, np.zeros((1, 5, 5, 3)), scenario)


def test_decoded_full_layout_obstacle() -> None:
    decoded, _ = heading_into_obstacle(CostConfig())
    assert decoded.obstacle_present.shape == (1, 5, 1) and decoded.obstacle_present.all()
    np.testing.assert_allclose(decoded.obstacle_relative[0, 0, 0], [65.0, 0.0], atol=1e-4)
    np.testing.assert_allclose(decoded.obstacle_radius[0, :, 0], 20.0, atol=1e-3)


def test_decoded_full_layout_without_obstacles_or_beyond_the_clip() -> None:
    sim = FormationSim(paper_scenario())
    sim.reset(seed=0)
    r = sim.last
    common = (r.z, r.reference_velocity, r.estimate, r.adjacency, r.avoiding, r.t / 200.0)
    # no obstacle; one 5 km away; one whose surface is within the 1000 m clip but whose centre
    # is not (the radius would decode wrong)
    beyond = r.z[0, 0, :2] + np.array([1020.0, 0.0])
    cases = (
        (np.zeros((0, 2)), np.zeros(0)),
        (np.array([[5000.0, 0.0]]), [30.0]),
        (beyond[None], [50.0]),
    )
    for centres, radii in cases:
        obs = build_observations(*common, sim.offsets, centres, np.asarray(radii), r.min_separation)
        decoded = decode_observations(obs, 5)
        assert not decoded.obstacle_present[0, 0].any()
        assert decoded.obstacle_radius[0, 0, 0] == 0.0


def test_exact_best_response_brakes_for_an_obstacle_ahead() -> None:
    """UAV 0 flies at 20 m/s towards an obstacle 45 m ahead (its reference is straight on): with
    the term (2 s lookahead) its exact best response brakes at the limit and is flagged as a
    refined (not certified) optimum; without the term it keeps its speed."""
    w_on = CostConfig(obstacle=100.0, obstacle_lookahead=10)
    _, off = heading_into_obstacle(CostConfig())
    _, on = heading_into_obstacle(w_on)
    br_off, br_on = best_response(off), best_response(on)
    assert abs(br_off.x[0, 0, 0, 0]) < 0.5
    assert br_on.x[0, 0, 0, 0] < -4.5  # brakes near the 5 m/s² limit
    assert not br_on.exact[0, 0] and br_on.evaluations[0, 0] > identification_evaluations(5)
    assert (
        on.cost.terms(br_on.x[:, :, None]).obstacle[0, 0, 0]
        < (on.cost.terms(br_off.x[:, :, None]).obstacle[0, 0, 0])
    )
    assert br_on.cost[0, 0] >= br_on.lower_bound[0, 0] - 1e-9
    # the policy's clearance radius is the decoded radius plus cost.obstacle_margin
    np.testing.assert_allclose(on.cost.obstacle_clearance[0, :, 0], 30.0, atol=1e-3)


def test_env_reward_and_info_carry_the_obstacle_term() -> None:
    """The reward is minus J_i's stage cost, obstacle term included: UAV 0 is put 4 m from an
    obstacle's surface (6 m inside the 10 m margin)."""
    import uav_formation_env

    env = uav_formation_env.parallel_env(cost={"obstacle": 2.0})
    env.reset(seed=0)
    sim = env.unwrapped.sim
    centre = np.asarray(env.unwrapped.scenario.avoidance.obstacles[0].center)
    radius = env.unwrapped.scenario.avoidance.obstacles[0].radius
    sim.z[0, 0, :2] = centre - np.array([radius + 4.0, 0.0])
    _, rewards, _, _, infos = env.step({a: np.zeros(3, np.float32) for a in env.agents})
    info = infos["uav_0"]
    expected = 2.0 * max(0.0, 10.0 - info["obstacle_distance"]) ** 2
    assert info["cost_obstacle"] == pytest.approx(expected, rel=1e-12) and expected > 0
    assert -rewards["uav_0"] == pytest.approx(info["J"], rel=1e-6)
    assert info["cost_obstacle"] > 0 and infos["uav_4"]["cost_obstacle"] == 0.0


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ({"obstacle": -1.0}, r"cost\.obstacle'.*>= 0"),
        ({"obstacle_margin": float("nan")}, r"cost\.obstacle_margin'.*finite"),
        ({"obstacle_lookahead": 2.5}, r"cost\.obstacle_lookahead'.*integer"),
        ({"obstacle_lookahead": -1}, r"cost\.obstacle_lookahead'.*integer"),
        ({"obstacle_lookahed": 3}, r"obstacle_lookahed"),
    ],
)
def test_obstacle_options_are_validated(override: dict, message: str) -> None:
    with pytest.raises((ValueError, TypeError), match=message):
        scenario_from_dict({"cost": override})


def test_obstacle_term_on_torch_equals_numpy() -> None:
    """The direct term, the screened fast evaluation and the stage term give the numpy numbers
    on torch (CPU)."""
    torch = pytest.importorskip("torch")
    rng = np.random.default_rng(11)
    b, n, h = 2, 3, 5
    w = CostConfig(obstacle=20.0, obstacle_lookahead=5)
    z0 = np.concatenate((rng.normal(0, 10, (b, n, 3)), rng.normal(0, 10, (b, n, 3))), axis=-1)
    centre = z0[:, :, None, :2] + rng.normal(20, 5, (b, n, 2, 2))
    clearance = rng.uniform(10, 30, (b, n, 2))
    neighbours = rollout(z0[:, :, None], rng.uniform(-5, 5, (b, n, 1, h, 3)), DT)[:, :, 0]
    adj = (rng.random((b, n, n)) < 0.5) * (1 - np.eye(n))
    ref = rng.normal(0, 20, (b, n, h + 1, 3))
    half = rng.uniform(1.0, 5.0, (b, n, 3))
    cand = rng.uniform(-1, 1, (b, n, 20, h, 3)) * half[:, :, None, None, :]
    arrays = (z0, neighbours, ref, adj, np.zeros((n, 6)))
    ours = prepare_horizon_cost(
        *arrays, w, DT, obstacle_centre=centre, obstacle_clearance=clearance
    )
    t = torch.from_numpy
    theirs = prepare_horizon_cost(
        *(t(a) for a in arrays), w, DT, obstacle_centre=t(centre), obstacle_clearance=t(clearance)
    )
    expected = ours.terms(cand).obstacle
    assert expected.max() > 0
    np.testing.assert_allclose(theirs.terms(t(cand)).obstacle.numpy(), expected, rtol=1e-12)
    np.testing.assert_allclose(
        theirs.quadratic(t(half)).total(t(cand)).numpy(),
        ours.quadratic(half).total(cand),
        rtol=1e-10,
    )
    surface = rng.uniform(-5, 20, (b, n))
    stage_args = (np.zeros((b, n, 3)), np.zeros((b, n, 3)), adj, np.zeros((n, 6)))
    z = z0 + 100.0 * np.arange(n)[None, :, None]  # far apart: no separation term
    got = stage_cost(t(z), *(t(a) for a in stage_args), w, obstacle_surface=t(surface))
    want = stage_cost(z, *stage_args, w, obstacle_surface=surface)
    np.testing.assert_allclose(got.obstacle.numpy(), want.obstacle, rtol=1e-14)
