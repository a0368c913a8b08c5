"""NashDMPCPolicy (docs/model.md §4.3, §5): warm start, trigger, one J_i, information pattern,
closed loop.

Also the per-receiver generalisation of the cost (``core/cost.py``) the policy relies on.
"""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest

from uav_formation_env.config import PAPER_OFFSETS, CostConfig
from uav_formation_env.config_io import paper_scenario, with_overrides
from uav_formation_env.core.cost import (
    anchored,
    formation_error_sq,
    horizon_cost,
    input_response,
    prepare_horizon_cost,
)
from uav_formation_env.core.dynamics import rollout
from uav_formation_env.core.observation import build_observations
from uav_formation_env.policies.dmpc import DEFAULT_THRESHOLD, NashDMPCPolicy, shift_warm_start
from uav_formation_env.policies.optimizers import (
    LFPIOConfig,
    PIOConfig,
    PSOConfig,
    n_evaluations,
)
from uav_formation_env.sim import FormationSim

NEVER = 1e300  # a threshold no J reaches: never triggered
ALWAYS = -1.0  # J >= 0 > threshold: always triggered


def observe(sim: FormationSim, z: np.ndarray | None = None) -> np.ndarray:
    """(B, N, dim) observations built from the sim's state exactly as the environment does
    (with the states ``z`` in place of the sim's if given)."""
    r, sc = sim.last, sim.scenario
    return build_observations(
        r.z if z is None else z,
        r.reference_velocity,
        r.estimate,
        r.adjacency,
        r.avoiding,
        r.t / sc.duration,
        sim.offsets,
        sim.obstacle_centers,
        sim.obstacle_radii,
        r.min_separation,
    )


def closed_loop(policy: NashDMPCPolicy, sim: FormationSim, steps: int, seed=0) -> list[np.ndarray]:
    sim.reset(seed=seed)
    actions = []
    for _ in range(steps):
        a = policy.act_batch(observe(sim))
        actions.append(a)
        sim.step(a * sim.u_max)
    return actions


@pytest.fixture(scope="module")
def scenario():
    return paper_scenario()


# ------------------------------------------------------------------------------------------------
# warm start (eq. 20)
# ------------------------------------------------------------------------------------------------


def test_shift_warm_start_by_hand() -> None:
    plan = np.arange(15, dtype=float).reshape(5, 3)  # u(k) = (3k, 3k+1, 3k+2)
    w = shift_warm_start(plan)
    np.testing.assert_array_equal(w[:4], plan[1:])
    np.testing.assert_array_equal(w[4], plan[4])  # last entry repeated
    batch = np.stack([plan, -plan])[None]  # (1, 2, 5, 3)
    np.testing.assert_array_equal(shift_warm_start(batch)[0, 1], -w)
    assert not np.shares_memory(w, plan)


def test_warm_start_is_zero_at_t0_and_the_shift_later(scenario) -> None:
    sim = FormationSim(scenario)
    sim.reset(seed=0)
    policy = NashDMPCPolicy(scenario, seed=0, threshold=NEVER)
    rng = np.random.default_rng(1)
    stale = rng.uniform(-1, 1, (1, 5, 5, 3))
    policy.plans = stale  # left over from an earlier episode
    actions = policy.act_batch(observe(sim))  # t = 0: plans cleared, W = 0
    np.testing.assert_array_equal(actions, 0.0)
    np.testing.assert_array_equal(policy.plans, 0.0)
    sim.step(actions * sim.u_max)
    policy.plans = stale  # pretend these were broadcast at t - δ
    actions = policy.act_batch(observe(sim))
    np.testing.assert_array_equal(policy.plans, shift_warm_start(stale))
    np.testing.assert_array_equal(actions, stale[:, :, 1] / scenario.dynamics.u_max)


# ------------------------------------------------------------------------------------------------
# event trigger and records
# ------------------------------------------------------------------------------------------------


def test_not_triggered_outputs_w_exactly_with_zero_evaluations(scenario) -> None:
    sim = FormationSim(scenario)
    policy = NashDMPCPolicy(scenario, seed=0)
    closed_loop(policy, sim, 3)
    policy.threshold = NEVER
    w = policy.warm_starts()
    policy.act_batch(observe(sim))
    np.testing.assert_array_equal(policy.plans, w)
    rec = policy.records()
    assert not rec.triggered[-1].any()
    np.testing.assert_array_equal(rec.evaluations[-1], 0)
    np.testing.assert_array_equal(rec.j_exec[-1], rec.j_pre[-1])


@pytest.mark.parametrize(
    "optimizer", ["lfpio", "pio", "pso", PIOConfig(map_compass_iters=5, landmark_iters=2)]
)
def test_triggered_runs_the_optimiser_and_never_gets_worse(scenario, optimizer) -> None:
    sim = FormationSim(scenario)
    policy = NashDMPCPolicy(scenario, optimizer=optimizer, seed=0, threshold=ALWAYS)
    closed_loop(policy, sim, 4)
    rec = policy.records()
    assert rec.triggered.all()
    np.testing.assert_array_equal(rec.evaluations, n_evaluations(policy.optimizer))
    assert (rec.j_exec <= rec.j_pre).all()
    assert (rec.j_exec < rec.j_pre).mean() > 0.9  # the optimiser really improves on W


def test_triggered_keeps_w_where_the_optimiser_answers_worse(scenario, monkeypatch) -> None:
    """The never-worse-than-W guard is the policy's own, not the optimiser's: an optimiser that
    answers the box corner (far worse than W, and claims cost 0) for UAVs 1, 3, 5 (rows 0, 2, 4)
    leaves them their warm starts with J_exec = J_pre; UAVs 2 and 4 take its better answers."""
    from uav_formation_env.policies import dmpc_step

    real = dmpc_step.minimise
    bad = np.array([0, 2, 4])

    def worse(cost_fn, x0, low, high, rng, config, **kwargs):
        result = real(cost_fn, x0, low, high, rng, config, **kwargs)
        x = result.x.copy()
        x[bad] = np.broadcast_to(high, x.shape)[bad]
        return replace(result, x=x, cost=np.zeros_like(result.cost))

    sim = FormationSim(scenario)
    policy = NashDMPCPolicy(scenario, seed=0, threshold=ALWAYS)
    closed_loop(policy, sim, 3)
    monkeypatch.setattr(dmpc_step, "minimise", worse)
    w = policy.warm_starts()
    policy.act_batch(observe(sim))
    rec = policy.records()
    assert rec.triggered[-1].all()
    np.testing.assert_array_equal(policy.plans[0, bad], w[0, bad])
    np.testing.assert_array_equal(rec.j_exec[-1, 0, bad], rec.j_pre[-1, 0, bad])
    good = np.array([1, 3])
    assert (rec.j_exec[-1, 0, good] < rec.j_pre[-1, 0, good]).all()
    assert not np.array_equal(policy.plans[0, good], w[0, good])
    assert (rec.j_exec <= rec.j_pre).all()
    np.testing.assert_array_equal(rec.evaluations[-1], n_evaluations(policy.optimizer))


def test_records_shapes_and_trigger_counts(scenario) -> None:
    sim = FormationSim(scenario, batch_size=2)
    policy = NashDMPCPolicy(scenario, seed=0)
    steps = 12
    closed_loop(policy, sim, steps, seed=[3, 4])
    rec = policy.records()
    for name in ("triggered", "j_pre", "j_exec", "evaluations"):
        assert getattr(rec, name).shape == (steps, 2, 5), name
    assert rec.time.shape == (steps, 2) and rec.wall_time.shape == (steps,)
    np.testing.assert_allclose(rec.time[:, 0], scenario.dynamics.dt * np.arange(steps))
    assert (rec.wall_time > 0).all()
    np.testing.assert_array_equal(rec.triggered, rec.j_pre > DEFAULT_THRESHOLD)
    np.testing.assert_array_equal(policy.trigger_counts(), rec.triggered.sum(axis=0))
    budget = n_evaluations(LFPIOConfig())
    np.testing.assert_array_equal(rec.evaluations, np.where(rec.triggered, budget, 0))
    assert (rec.j_exec <= rec.j_pre).all()


def test_mixed_triggers_keep_w_for_the_untriggered(scenario) -> None:
    sim = FormationSim(scenario)
    policy = NashDMPCPolicy(scenario, seed=0)
    closed_loop(policy, sim, 5)
    j = policy.records().j_pre[-1, 0]
    policy.threshold = float(np.median(j))  # about half triggered
    w = policy.warm_starts()
    policy.act_batch(observe(sim))
    rec = policy.records()
    trig = rec.triggered[-1, 0]
    assert trig.any() and not trig.all()
    np.testing.assert_array_equal(policy.plans[0, ~trig], w[0, ~trig])
    assert (rec.j_exec[-1, 0, trig] < rec.j_pre[-1, 0, trig]).all()


def test_search_box_respects_the_compensation() -> None:
    """|u_n,c| <= u_max - |u_d,c| with u_d = -estimate (docs/model.md §1.5)."""
    scenario = paper_scenario()
    sim = FormationSim(scenario)
    sim.reset(seed=0)
    obs = observe(sim)
    obs[..., 9:12] = np.array([4.0, -2.0, 0.0]) / 0.5  # estimate (4, -2, 0) m/s^2 for everyone
    policy = NashDMPCPolicy(scenario, seed=0, threshold=ALWAYS)
    policy.act_batch(obs)
    plans = policy.plans  # W = 0 at t = 0 is inside the box, so the output is too
    assert np.abs(plans[..., 0]).max() <= 1.0 + 1e-12
    assert np.abs(plans[..., 1]).max() <= 3.0 + 1e-12
    assert np.abs(plans[..., 2]).max() <= 5.0 + 1e-12


# ------------------------------------------------------------------------------------------------
# one definition of J_i
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("mirrored", [False, True])
def test_j_pre_equals_horizon_cost_on_global_data(mirrored: bool) -> None:
    """The policy's J_pre (own frame, float32 observations) = horizon_cost in global coordinates,
    including steps with an avoidance reference held over the horizon. Receiver i predicts a
    neighbour with its plan and any other UAV (for the separation term) with zero inputs."""
    scenario = with_overrides(paper_scenario(), {"formation.mirrored_offsets": mirrored})
    sim = FormationSim(scenario)
    sim.reset(seed=0)
    policy = NashDMPCPolicy(scenario, seed=0)
    dt, cost = scenario.dynamics.dt, scenario.cost
    saw_avoiding = False
    for _ in range(60):
        w = np.zeros((1, 5, 5, 3)) if sim.t[0] == 0.0 else policy.warm_starts()
        r = sim.last
        plans = np.where(r.adjacency[..., None, None] > 0, w[:, None], 0.0)  # (B, i, j, H, 3)
        neighbours = rollout(np.broadcast_to(r.z[:, None], plans.shape[:3] + (6,)), plans, dt)

        def j_of(sequences, r=r, neighbours=neighbours):
            preview = sim.reference_preview()
            terms = horizon_cost(
                sequences[:, :, None],
                r.z,
                neighbours,
                preview,
                r.adjacency,
                scenario.formation.slot_offsets,
                cost,
                dt,
            )
            return terms.total[..., 0]

        expected = j_of(w)
        saw_avoiding |= bool(r.avoiding.any())
        actions = policy.act_batch(observe(sim))
        got = policy.records().j_pre[-1]
        np.testing.assert_allclose(got, expected, rtol=2e-5, atol=1e-4)
        output = policy.plans
        j_exec = j_of(output)
        np.testing.assert_allclose(policy.records().j_exec[-1], j_exec, rtol=2e-5, atol=1e-4)
        sim.step(actions * sim.u_max)
    assert saw_avoiding, "the check should cover an avoidance phase (O1 at about 10 s)"


# ------------------------------------------------------------------------------------------------
# determinism and information pattern
# ------------------------------------------------------------------------------------------------


def test_same_seed_same_actions_different_seed_differs(scenario) -> None:
    runs = {}
    for name, seed in (("a", 5), ("b", 5), ("c", 6)):
        policy = NashDMPCPolicy(scenario, seed=seed)
        runs[name] = np.stack(closed_loop(policy, FormationSim(scenario), 15))
    np.testing.assert_array_equal(runs["a"], runs["b"])
    assert not np.array_equal(runs["a"], runs["c"])


def test_only_neighbours_plans_matter(scenario) -> None:
    """UAV 1 (index 0) receives from UAVs 2, 4, 5 (H0): perturbing UAV 3's plan (index 2) leaves
    its J_pre and action unchanged, perturbing UAV 2's (index 1) changes them. Every UAV is
    triggered, so the optimiser batch (and the shared random stream) is the same in all runs."""
    sim = FormationSim(scenario)
    base = NashDMPCPolicy(scenario, seed=0, threshold=ALWAYS)
    closed_loop(base, sim, 8)
    obs = observe(sim)  # built from the sim state; the policy sees nothing else
    decoded_neighbours = obs[0, 0, 19::7]  # flags of UAVs 2..5 as UAV 1 sees them
    np.testing.assert_array_equal(decoded_neighbours, [1, 0, 1, 1])
    rng = np.random.default_rng(7)

    def act_with(perturb: int | None) -> tuple[np.ndarray, np.ndarray]:
        policy = copy.deepcopy(base)
        if perturb is not None:
            plans = policy.plans
            plans[0, perturb] += rng.uniform(-2, 2, (5, 3))
            policy.plans = plans
        actions = policy.act_batch(obs)
        return actions[0, 0], policy.records().j_pre[-1, 0, 0]

    a_ref, j_ref = act_with(None)
    a_non, j_non = act_with(2)
    a_nbr, j_nbr = act_with(1)
    np.testing.assert_array_equal(a_non, a_ref)
    assert j_non == j_ref
    assert j_nbr != j_ref
    assert not np.array_equal(a_nbr, a_ref)


def test_only_neighbours_plans_matter_within_the_separation_distance(scenario) -> None:
    """UAV 3 (index 2), not a neighbour of UAV 1 (index 0), put within d_s of it: its position
    now enters UAV 1's J_i (the separation term over every sensed UAV), but its broadcast plan
    still does not: UAV 1 predicts it with zero inputs, so perturbing the plan changes neither
    UAV 1's J_pre nor its action (with the plan used, the predicted distances, and so J_pre,
    would change)."""
    sim = FormationSim(scenario)
    base = NashDMPCPolicy(scenario, seed=0, threshold=ALWAYS)
    closed_loop(base, sim, 8)
    d_s = scenario.cost.separation_distance
    z = sim.last.z.copy()
    z[0, 2, :3] = z[0, 0, :3] + np.array([0.0, 0.5 * d_s, 0.0])
    close, apart = observe(sim, z), observe(sim)
    assert close[0, 0, 19 + 7 * 1] == 0.0  # UAV 3 is not a neighbour of UAV 1
    assert sim.last.min_separation.min() > d_s  # in formation no pair is within d_s
    rng = np.random.default_rng(7)

    def act_with(obs: np.ndarray, perturb: bool) -> tuple[np.ndarray, float]:
        policy = copy.deepcopy(base)
        if perturb:
            plans = policy.plans
            plans[0, 2] += rng.uniform(-2, 2, (5, 3))
            policy.plans = plans
        actions = policy.act_batch(obs)
        return actions[0, 0], policy.records().j_pre[-1, 0, 0]

    a_ref, j_ref = act_with(close, perturb=False)
    a_plan, j_plan = act_with(close, perturb=True)
    a_far, j_far = act_with(apart, perturb=False)
    np.testing.assert_array_equal(a_plan, a_ref)
    assert j_plan == j_ref
    assert j_ref > j_far  # the separation term of the pair we placed
    assert not np.array_equal(a_ref, a_far)


def test_policy_module_imports_neither_sim_nor_env() -> None:
    """No import chain from the policy to the sim, the env or the CLI (the package's own
    ``__init__`` is not a dependency of the module; import-linter checks the same)."""
    grimp = pytest.importorskip("grimp")
    graph = grimp.build_graph("uav_formation_env")
    forbidden = [
        m for m in graph.modules if m.split(".")[1:2] in (["sim"], ["env"], ["envs"], ["cli"])
    ]
    assert "uav_formation_env.sim" in forbidden
    policy_modules = [m for m in graph.modules if m.startswith("uav_formation_env.policies")]
    assert "uav_formation_env.policies.broadcast" in policy_modules
    for policy_module in policy_modules:
        for target in forbidden:
            assert not graph.chain_exists(importer=policy_module, imported=target), target


# ------------------------------------------------------------------------------------------------
# closed loop, APIs
# ------------------------------------------------------------------------------------------------


def formation_spread(sim: FormationSim) -> float:
    """Largest distance of a UAV's anchored position from the swarm's mean [m] (0 in formation)."""
    a = anchored(sim.last.z, sim.offsets)[..., :3]
    return float(np.linalg.norm(a - a.mean(axis=1, keepdims=True), axis=-1).max())


@pytest.mark.parametrize("obstacles", [False, True])
def test_closed_loop_reduces_formation_error(obstacles: bool) -> None:
    """100 steps (20 s) with the observer on. Without obstacles the formation converges; with
    them the swarm splits at O1 (about 10-15 s) and re-forms, so compare before the encounter."""
    scenario = paper_scenario()
    if not obstacles:
        scenario = with_overrides(scenario, {"avoidance.obstacles": []})
    sim = FormationSim(scenario)
    policy = NashDMPCPolicy(scenario, seed=0)
    sim.reset(seed=1)
    spread0, cost0 = formation_spread(sim), sim.last.cost.formation.sum()
    steps = 100 if not obstacles else 45
    actions = np.stack(closed_loop(policy, sim, steps, seed=1))
    assert np.abs(actions).max() <= 1.0
    spread, cost = formation_spread(sim), sim.last.cost.formation.sum()
    assert spread < (0.1 if not obstacles else 0.4) * spread0, (spread0, spread)
    assert cost < (0.01 if not obstacles else 0.2) * cost0, (cost0, cost)
    velocity_error = np.abs(sim.last.z[..., 3:] - sim.last.reference_velocity).max()
    assert velocity_error < (1.0 if not obstacles else 3.0), velocity_error
    assert not sim.last.collision.any()


def test_predict_for_sb3_and_act_dict(scenario) -> None:
    sim = FormationSim(scenario, batch_size=2)
    sim.reset(seed=0)
    obs = observe(sim)  # (2, 5, dim)
    a = NashDMPCPolicy(scenario, seed=3)
    b = copy.deepcopy(a)
    flat = obs.reshape(10, -1)
    actions, state = a.predict(flat, state=None, episode_start=np.ones(10, dtype=bool))
    assert actions.shape == (10, 3) and actions.dtype == np.float32 and state is None
    np.testing.assert_allclose(actions, b.act_batch(obs).reshape(10, 3), rtol=1e-6)
    with pytest.raises(ValueError):
        a.predict(flat[:7])
    single = NashDMPCPolicy(scenario, seed=3)
    out = single.act({f"uav_{i}": obs[0, i] for i in range(5)})
    assert sorted(out) == [f"uav_{i}" for i in range(5)]
    assert all(v.shape == (3,) and v.dtype == np.float32 for v in out.values())
    with pytest.raises(KeyError):
        single.act({"uav_0": obs[0, 0]})


def test_automatic_reset_at_t0_clears_plans_and_records(scenario) -> None:
    sim = FormationSim(scenario)
    policy = NashDMPCPolicy(scenario, seed=0)
    closed_loop(policy, sim, 5)
    assert len(policy.records().j_pre) == 5 and np.abs(policy.plans).max() > 0
    sim.reset(seed=1)
    policy.act_batch(observe(sim))
    assert len(policy.records().j_pre) == 1


def test_options_and_errors(scenario) -> None:
    assert isinstance(NashDMPCPolicy(scenario, optimizer="PIO").optimizer, PIOConfig)
    assert isinstance(NashDMPCPolicy(scenario, optimizer="pso").optimizer, PSOConfig)
    assert n_evaluations(PSOConfig()) == n_evaluations(LFPIOConfig())  # equal budgets
    with pytest.raises(ValueError):
        NashDMPCPolicy(scenario, optimizer="ga")
    with pytest.raises(ValueError):
        NashDMPCPolicy(scenario, inner_rounds=0)
    with pytest.raises(ValueError):
        NashDMPCPolicy(scenario, population_cost="fast")
    with pytest.raises(ValueError):
        NashDMPCPolicy(scenario).act_batch(np.zeros((1, 4, 40)))


def test_inner_rounds(scenario) -> None:
    sim = FormationSim(scenario)
    policy = NashDMPCPolicy(scenario, seed=0, inner_rounds=3)
    actions = np.stack(closed_loop(policy, sim, 3))
    rec = policy.records()
    budget = n_evaluations(LFPIOConfig())
    assert (rec.evaluations % budget == 0).all() and rec.evaluations.max() > budget
    assert np.isfinite(rec.j_exec).all() and np.abs(actions).max() <= 1.0


def test_direct_and_quadratic_population_costs_agree(scenario) -> None:
    sim = FormationSim(scenario)
    sim.reset(seed=2)
    obs = observe(sim)
    out = {}
    for mode in ("quadratic", "direct"):
        policy = NashDMPCPolicy(scenario, seed=0, population_cost=mode)
        out[mode] = (policy.act_batch(obs), policy.records().j_exec)
    np.testing.assert_allclose(out["quadratic"][0], out["direct"][0], atol=1e-7)
    np.testing.assert_allclose(out["quadratic"][1], out["direct"][1], rtol=1e-9)


# ------------------------------------------------------------------------------------------------
# core/cost.py: per-receiver views, prepared cost, quadratic coefficients
# ------------------------------------------------------------------------------------------------


def _random_problem(rng: np.random.Generator, b: int = 2, n: int = 5, h: int = 5):
    z0 = np.concatenate((800 + rng.normal(0, 10, (b, n, 3)), rng.normal(0, 20, (b, n, 3))), -1)
    plans = rng.uniform(-5, 5, (b, n, h, 3))
    neighbours = rollout(z0[:, :, None], plans[:, :, None], 0.2)[:, :, 0]  # (B, N, H+1, 6)
    reference = rng.normal(0, 20, (b, n, h + 1, 3))
    adjacency = (rng.random((b, n, n)) < 0.6).astype(float)
    adjacency[:, np.arange(n), np.arange(n)] = 0.0
    return z0, plans, neighbours, reference, adjacency


def test_per_receiver_views_in_own_frames_equal_the_global_form() -> None:
    rng = np.random.default_rng(0)
    z0, plans, neighbours, ref, adj = _random_problem(rng)
    offsets = np.asarray(PAPER_OFFSETS)
    cand = rng.uniform(-5, 5, (2, 5, 4, 5, 3))
    w = CostConfig()
    glob = horizon_cost(cand, z0, neighbours, ref, adj, offsets, w, 0.2)
    # receiver i's frame: everything translated by -p_i (positions only)
    shift = np.zeros_like(z0)
    shift[..., :3] = z0[..., :3]
    z_own = z0 - shift
    views = neighbours[:, None] - shift[:, :, None, None, :]  # (B, N_recv, N_send, H+1, 6)
    local = horizon_cost(cand, z_own, views, ref, adj, offsets, w, 0.2)
    for name, value in glob.as_dict().items():
        np.testing.assert_allclose(getattr(local, name), value, rtol=1e-9, atol=1e-8)


def test_formation_error_sq_per_receiver_against_brute_force() -> None:
    rng = np.random.default_rng(1)
    b, n, p, h1 = 2, 4, 3, 6
    own = rng.normal(0, 10, (b, n, p, h1, 6))
    views = rng.normal(0, 10, (b, n, n, h1, 6))  # every receiver sees its own, different views
    adj = (rng.random((b, n, n)) < 0.7).astype(float)
    got = formation_error_sq(own, views, adj, per_receiver=True)
    expected = np.zeros((b, n, p, h1))
    for k in range(b):
        for i in range(n):
            for j in range(n):
                expected[k, i] += adj[k, i, j] * ((own[k, i] - views[k, i, j]) ** 2).sum(-1)
    np.testing.assert_allclose(got, expected, rtol=1e-10)
    # identical views for every receiver reduce to the per-sender form
    same = np.broadcast_to(views[:, :1], views.shape)
    np.testing.assert_allclose(
        formation_error_sq(own, same, adj, per_receiver=True),
        formation_error_sq(own, views[:, 0], adj),
        rtol=1e-10,
    )


def test_prepared_cost_prediction_take_and_quadratic() -> None:
    rng = np.random.default_rng(2)
    z0, plans, neighbours, ref, adj = _random_problem(rng)
    offsets = np.asarray(PAPER_OFFSETS)
    w = CostConfig()
    prepared = prepare_horizon_cost(z0, neighbours, ref, adj, offsets, w, 0.2)
    cand = rng.uniform(-5, 5, (2, 5, 6, 5, 3))
    np.testing.assert_allclose(
        prepared.predict(cand), rollout(z0[:, :, None], cand, 0.2), rtol=1e-12, atol=1e-9
    )
    assert input_response(5, 0.2).shape == (15, 36)
    exact = prepared.terms(cand).total
    np.testing.assert_allclose(
        exact, horizon_cost(cand, z0, neighbours, ref, adj, offsets, w, 0.2).total
    )
    quadratic = prepared.quadratic()
    np.testing.assert_allclose(quadratic.total(cand), exact, rtol=1e-11)
    np.testing.assert_allclose(quadratic.hessian, np.swapaxes(quadratic.hessian, -1, -2))
    index = np.array([7, 0, 3])  # flattened (copy, UAV): (1, 2), (0, 0), (0, 3)
    sub = prepared.take(index)
    flat = cand.reshape(10, 6, 5, 3)[index][None]
    np.testing.assert_allclose(sub.terms(flat).total[0], exact.reshape(10, 6)[index], rtol=1e-12)
    np.testing.assert_allclose(
        quadratic.take(index).total(flat)[0], exact.reshape(10, 6)[index], rtol=1e-11
    )


# ------------------------------------------------------------------------------------------------
# separation term in the MPC (docs/deviations.md §5)
# ------------------------------------------------------------------------------------------------


def close_start(scenario, gap: float = 3.0) -> tuple[FormationSim, np.ndarray, np.ndarray]:
    """t = 0 with UAV 3 (index 2, not a neighbour of UAV 1) put ``gap`` m beside UAV 1.

    Returns the sim, the observations and the states they were built from.
    """
    sim = FormationSim(scenario)
    sim.reset(seed=0)
    z = sim.last.z.copy()
    z[0, 2, :3] = z[0, 0, :3] + np.array([0.0, gap, 0.0])
    return sim, observe(sim, z), z


def test_j_pre_contains_the_separation_term_of_every_sensed_uav() -> None:
    """At t = 0 (W = 0, equal velocities) every UAV's prediction keeps its distances, so the
    separation term of receiver i is s (H+1) Σ_{j≠i} max(0, d_s - d_ij)² over ALL j, neighbours
    or not; it is the only difference to the paper's J_i."""
    on = paper_scenario()
    off = with_overrides(on, {"cost.separation": 0.0})
    _, obs, z = close_start(on)
    assert obs[0, 0, 19 + 7 * 1] == 0.0  # UAV 3 is not a neighbour of UAV 1
    j_pre = {}
    for name, scenario in (("on", on), ("off", off)):
        policy = NashDMPCPolicy(scenario, seed=0, threshold=NEVER)
        policy.act_batch(obs)
        j_pre[name] = policy.records().j_pre[0, 0]
    p = z[0, :, :3]
    d = np.linalg.norm(p[:, None] - p[None], axis=-1) + np.diag(np.full(5, np.inf))
    c = on.cost
    expected = c.separation * (c.horizon + 1) * (np.maximum(c.separation_distance - d, 0) ** 2)
    expected = expected.sum(axis=1)
    assert expected[0] >= c.separation * 6 * 25.0 and expected[2] > 0  # the pair we placed
    np.testing.assert_allclose(j_pre["on"] - j_pre["off"], expected, rtol=1e-5, atol=1e-3)


def test_population_costs_agree_with_the_separation_term_active() -> None:
    scenario = paper_scenario()
    _, obs, _ = close_start(scenario, gap=2.5)
    out = {}
    for mode in ("quadratic", "direct"):
        policy = NashDMPCPolicy(scenario, seed=0, threshold=ALWAYS, population_cost=mode)
        out[mode] = (policy.act_batch(obs), policy.records().j_exec, policy.plans)
    np.testing.assert_allclose(out["quadratic"][0], out["direct"][0], atol=1e-7)
    np.testing.assert_allclose(out["quadratic"][1], out["direct"][1], rtol=1e-9)
    # the two UAVs we placed 2.5 m apart are pushed apart along y by their first inputs
    first = out["quadratic"][2][0, :, 0]
    assert first[0, 1] < 0.0 < first[2, 1]


def test_separation_prevents_the_start_collisions() -> None:
    """Seed 1 of the paper scenario: with the paper's J_i two UAVs come within 2 m while the swarm
    converges from the random start box (observer off, LFPIO); with the separation term they do
    not. 60 steps (12 s) cover the convergence."""
    closest = {}
    for name, separation in (("paper", 0.0), ("ours", CostConfig().separation)):
        scenario = with_overrides(
            paper_scenario(), {"observer.enabled": False, "cost.separation": separation}
        )
        sim = FormationSim(scenario)
        policy = NashDMPCPolicy(scenario, seed=1)
        sim.reset(seed=1)
        low = np.inf
        for _ in range(60):
            sim.step(policy.act_batch(observe(sim)) * sim.u_max)
            low = min(low, float(sim.last.min_separation.min()))
        closest[name] = low
    assert closest["paper"] < scenario.collision.uav_distance
    assert closest["ours"] > scenario.collision.uav_distance


# ------------------------------------------------------------------------------------------------
# exact best-response optimisers (issue 6; more in tests/test_best_response.py)
# ------------------------------------------------------------------------------------------------


def test_exact_and_nash_optimizer_names_and_records(scenario) -> None:
    from uav_formation_env.policies.best_response import ExactConfig
    from uav_formation_env.policies.dmpc import POLICY_OPTIMIZERS
    from uav_formation_env.policies.nash import NashConfig

    assert POLICY_OPTIMIZERS == ("pio", "lfpio", "pso", "exact", "nash")
    assert isinstance(NashDMPCPolicy(scenario, optimizer="EXACT").optimizer, ExactConfig)
    assert isinstance(NashDMPCPolicy(scenario, optimizer="nash").optimizer, NashConfig)
    with pytest.raises(ValueError):
        NashDMPCPolicy(scenario, optimizer="nash", inner_rounds=3)
    # the one-shot optimisers record no Nash sweeps
    policy = NashDMPCPolicy(scenario, seed=0)
    closed_loop(policy, FormationSim(scenario), 2)
    rec = policy.records()
    np.testing.assert_array_equal(rec.nash_iterations, np.zeros((2, 1), dtype=np.int64))
    assert rec.nash_converged.shape == (2, 1) and rec.nash_converged.all()
    empty = NashDMPCPolicy(scenario).records()
    assert empty.nash_iterations.shape == (0, 1)


def test_exact_optimizer_with_inner_rounds_and_the_separation_term() -> None:
    """The two UAVs placed 2.5 m apart are pushed apart by the exact answers too, and K = 3
    rounds of exact best responses spend one identification (136 evaluations) per round."""
    scenario = paper_scenario()
    _, obs, _ = close_start(scenario, gap=2.5)
    policy = NashDMPCPolicy(scenario, "exact", threshold=ALWAYS, inner_rounds=3)
    policy.act_batch(obs)
    first = policy.plans[0, :, 0]
    assert first[0, 1] < 0.0 < first[2, 1]
    rec = policy.records()
    assert (rec.j_exec <= rec.j_pre).all()
    assert (rec.evaluations >= 3 * 136).all()
    np.testing.assert_array_equal(rec.evaluations[0, 0, [1, 3, 4]], 3 * 136)
