"""Batched evaluation: the runner, the policy adapters, metrics, and ``uav-formation evaluate``."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from uav_formation_env.cli import main as cli_main
from uav_formation_env.config_io import paper_scenario, with_overrides
from uav_formation_env.episode import observations_of
from uav_formation_env.evaluation import (
    RECORD_COLUMNS,
    HeuristicPolicy,
    RandomPolicy,
    make_policy,
    read_records,
    run_episodes,
    summarise,
)
from uav_formation_env.policies.heuristic import consensus_pd
from uav_formation_env.sim import FormationSim

SUMMARY_KEYS = {
    "triggers_per_uav",
    "triggers_mean",
    "realised_cost_per_uav",
    "realised_cost_mean",
    "formation_rmse_m",
    "min_obstacle_surface_distance_m",
    "min_obstacle_center_distance_m",
    "min_separation_m",
    "collisions",
    "observer_rms_error",
    "events",
    "wall_time_per_step_s",
    "wall_time_per_step_per_episode_s",
    "seconds_per_episode",
    "realised_cost_terms",
}


def short(duration: float = 16.0, **overrides):
    return with_overrides(paper_scenario(), {"duration": duration, **overrides})


@pytest.mark.parametrize("policy", ["heuristic", "random"])
def test_cli_evaluate_writes_records_and_summary(tmp_path, policy):
    out = tmp_path / policy
    argv = ["evaluate", "--policy", policy, "--seeds", "2", "--duration", "16", "--quiet"]
    assert cli_main([*argv, "--out", str(out)]) == 0
    rows = read_records(out / "records.csv")
    assert list(rows[0]) == RECORD_COLUMNS
    assert len(rows) == 2 * 80 * 5  # seeds x steps x UAVs
    assert {r["seed"] for r in rows} == {"0", "1"}
    assert rows[0]["step"] == "1" and rows[-1]["step"] == "80" and rows[-1]["uav"] == "5"
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary) >= SUMMARY_KEYS
    assert summary["seeds"] == [0, 1] and summary["n_steps"] == 80
    assert summary["triggers_per_uav"] is None  # no event trigger outside the DMPC
    assert len(summary["realised_cost_per_uav"]) == 5
    assert all(c > 0 for c in summary["realised_cost_per_uav"])
    assert summary["formation_rmse_m"] > 0 and summary["min_separation_m"] > 0
    assert summary["wall_time_per_step_s"] > 0
    assert 0 < summary["observer_rms_error"] < 0.05  # the paper's scenario has the observer on
    assert summary["events"]["O1"]["activate_s"] == pytest.approx(10.0, abs=1.5)
    assert (out / "trajectories.png").stat().st_size > 10_000


def test_cli_evaluate_compare_flies_the_reference_on_the_same_seeds(tmp_path, capsys):
    argv = ["evaluate", "--seeds", "2", "--duration", "16", "--quiet"]
    alone, compared = tmp_path / "heuristic", tmp_path / "random"
    assert cli_main([*argv, "--policy", "heuristic", "--out", str(alone)]) == 0
    capsys.readouterr()
    compare = ["--policy", "random", "--compare", "heuristic", "--out", str(compared)]
    assert cli_main([*argv, *compare]) == 0
    printed = capsys.readouterr().out
    heuristic = json.loads((alone / "summary.json").read_text())
    summary = json.loads((compared / "summary.json").read_text())
    reference = summary["reference"]
    assert reference["policy"] == "heuristic"
    assert reference["realised_cost_mean"] == heuristic["realised_cost_mean"]
    assert reference["completed"] == heuristic["mission"]["completed"]
    ratio = summary["realised_cost_mean"] / heuristic["realised_cost_mean"]
    assert reference["cost_ratio"] == pytest.approx(ratio, rel=1e-12)
    assert f"{ratio:.3g} x HEURISTIC's {heuristic['realised_cost_mean']:.4g}" in printed


def test_cli_evaluate_compare_with_an_unknown_policy_writes_nothing(tmp_path, capsys):
    out = tmp_path / "eval"
    argv = ["evaluate", "--policy", "heuristic", "--compare", "nonesuch", "--seeds", "1"]
    assert cli_main([*argv, "--duration", "4", "--quiet", "--out", str(out)]) == 2
    assert "nonesuch" in capsys.readouterr().err
    assert not out.exists()


def test_random_policy_costs_more_than_heuristic(tmp_path):
    costs = {}
    for policy in ("heuristic", "random"):
        out = tmp_path / policy
        argv = ["evaluate", "--policy", policy, "--seeds", "2", "--duration", "16", "--quiet"]
        assert cli_main([*argv, "--out", str(out)]) == 0
        summary = json.loads((out / "summary.json").read_text())
        costs[policy] = summary
    heuristic, random = costs["heuristic"], costs["random"]
    assert random["realised_cost_mean"] > 3 * heuristic["realised_cost_mean"]
    assert random["formation_rmse_m"] > heuristic["formation_rmse_m"]
    assert heuristic["collisions"] == 0
    assert heuristic["min_obstacle_surface_distance_m"] > 0


def test_observer_off_gives_null_observer_error(tmp_path):
    argv = ["evaluate", "--policy", "heuristic", "--observer", "off", "--seeds", "1"]
    assert cli_main([*argv, "--duration", "4", "--quiet", "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["observer"] is False and summary["observer_rms_error"] is None


def test_batched_heuristic_equals_one_seed_at_a_time():
    scenario = short(12.0)
    seeds = [3, 4, 7]
    batch = run_episodes(scenario, HeuristicPolicy(scenario), seeds)
    for b, seed in enumerate(seeds):
        single = run_episodes(scenario, HeuristicPolicy(scenario), [seed])
        np.testing.assert_array_equal(batch.stage_cost[:, b], single.stage_cost[:, 0])
        np.testing.assert_array_equal(batch.z[:, b], single.z[:, 0])
        np.testing.assert_array_equal(batch.estimate[:, b], single.estimate[:, 0])
        np.testing.assert_array_equal(batch.activation_time[b], single.activation_time[0])
    assert batch.stage_cost.shape == (60, 3, 5)
    assert batch.z.shape == (61, 3, 5, 6)


def test_heuristic_from_observations_matches_the_law_on_simulator_arrays():
    scenario = short(30.0)
    sim = FormationSim(scenario, batch_size=4)
    result = sim.reset(seed=11)
    policy = HeuristicPolicy(scenario)
    worst = 0.0
    for _ in range(150):  # through the O1 split (different adjacency per group)
        action = policy.act_batch(observations_of(sim, result))
        direct = consensus_pd(
            result.z, result.reference_velocity, result.adjacency, sim.offsets, sim.u_max
        )
        worst = max(worst, float(np.abs(action * sim.u_max - direct).max()))
        result = sim.step(action * sim.u_max)
    assert worst < 1e-3  # float32 observations only


def test_realised_cost_terms_add_up_to_j_and_energy_is_r_u_squared():
    scenario = short(8.0)
    batch = run_episodes(scenario, make_policy("heuristic", scenario), [0, 1])
    summary = summarise(batch)
    terms = summary["realised_cost_terms"]
    assert set(terms) == {"formation", "energy", "terminal", "velocity", "separation", "obstacle"}
    assert sum(terms.values()) == pytest.approx(summary["realised_cost_mean"], rel=1e-12)
    # r Σ_k ||u_i(k)||² by hand from the recorded formation inputs, mean over seeds and UAVs
    energy = scenario.cost.r * (batch.u_n**2).sum(axis=(0, 3)).mean()
    assert terms["energy"] == pytest.approx(energy, rel=1e-12) and energy > 0


def test_dmpc_records_give_trigger_counts_and_wall_time():
    scenario = short(4.0)
    policy = make_policy("pio", scenario, seed=0)
    batch = run_episodes(scenario, policy, [0, 1], policy_name="pio")
    summary = summarise(batch)
    assert batch.triggered.shape == (20, 2, 5)
    counts = np.asarray(summary["triggers_per_uav_per_seed"])
    np.testing.assert_array_equal(counts, policy.trigger_counts())
    assert summary["triggers_mean"] == pytest.approx(counts.mean())
    assert 0 < summary["optimiser_cost_ratio_median"] <= 1.0
    assert summary["policy_time_per_step_s"] > 0


def test_run_episodes_rejects_bad_actions_and_policy_names():
    scenario = short(2.0)

    class Wrong:
        def act_batch(self, obs):
            return np.zeros((obs.shape[0], 3))

    with pytest.raises(ValueError, match="shape"):
        run_episodes(scenario, Wrong(), [0])
    with pytest.raises(ValueError, match="unknown policy"):
        make_policy("no-such-policy", scenario)
    with pytest.raises(ValueError, match="seed"):
        run_episodes(scenario, RandomPolicy(0), [])


def test_one_registry_of_policy_names():
    """Every list of policy names is the registry's: make_policy builds each name, the
    evaluation package re-exports the policies' objects, and the reproduction's variants and
    labels are built from the names."""
    import uav_formation_env.evaluation as evaluation
    import uav_formation_env.policies as policies
    from uav_formation_env.policies import registry
    from uav_formation_env.policies.dmpc import POLICY_OPTIMIZERS, NashDMPCPolicy
    from uav_formation_env.reproduce.variants import GAME_VARIANTS, LABELS, VARIANTS

    assert (*registry.DMPC_OPTIMIZERS, *registry.SIMPLE_POLICIES) == registry.POLICY_NAMES
    assert POLICY_OPTIMIZERS is registry.DMPC_OPTIMIZERS
    assert set(registry.POLICY_LABELS) == set(registry.POLICY_NAMES)
    assert all(name in registry.POLICY_HELP for name in registry.POLICY_NAMES)
    assert set(registry.PAPER_OPTIMIZERS) <= set(registry.DMPC_OPTIMIZERS)
    scenario = short(2.0)
    for name in registry.DMPC_OPTIMIZERS:
        policy = make_policy(name.upper(), scenario)
        assert isinstance(policy, NashDMPCPolicy)
        assert isinstance(policy.optimizer, registry.DMPC_SOLVERS[name])
    assert isinstance(make_policy("heuristic", scenario), HeuristicPolicy)
    assert isinstance(make_policy("random", scenario), RandomPolicy)
    for name in ("make_policy", "HeuristicPolicy", "RandomPolicy", "SB3Policy", "POLICY_NAMES"):
        assert getattr(evaluation, name) is getattr(policies, name)
    with pytest.raises(ValueError, match="unknown optimizer"):
        NashDMPCPolicy(scenario, optimizer="heuristic")
    used = {name for name, _ in {**VARIANTS, **GAME_VARIANTS}.values()}
    assert used == set(registry.DMPC_OPTIMIZERS)
    assert LABELS["nash_nftsmo"] == registry.POLICY_LABELS["nash"] + " + NFTSMO"


def test_sb3_model_with_vecnormalize(tmp_path):
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from uav_formation_env import vec_env

    venv = VecNormalize(vec_env("paper", num_copies=1, duration=4.0))
    model = PPO("MlpPolicy", venv, n_steps=16, batch_size=16, seed=0, device="cpu")
    model.learn(32)  # a few updates so the normalisation statistics move
    model.save(tmp_path / "model.zip")
    venv.save(str(tmp_path / "vecnormalize.pkl"))

    with pytest.raises(ValueError, match="refusing to unpickle .*--trust-pickle"):
        make_policy(str(tmp_path / "model.zip"), short(4.0))
    policy = make_policy(str(tmp_path / "model.zip"), short(4.0), trust_pickle=True)
    assert policy.algo == "PPO" and policy.stats is not None
    out = tmp_path / "eval"
    argv = ["evaluate", "--policy", str(tmp_path / "model.zip"), "--seeds", "2", "--trust-pickle"]
    assert cli_main([*argv, "--duration", "4", "--quiet", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n_steps"] == 20 and len(summary["realised_cost_per_uav"]) == 5


def test_summary_is_standard_json_when_the_episode_ends_before_the_observer_window(tmp_path):
    argv = ["evaluate", "--policy", "pio", "--observer", "on", "--seeds", "1", "--duration", "4"]
    assert cli_main([*argv, "--quiet", "--out", str(tmp_path)]) == 0

    def reject(constant):
        raise AssertionError(f"non-standard JSON constant {constant}")

    text = (tmp_path / "summary.json").read_text()
    summary = json.loads(text, parse_constant=reject)
    assert summary["observer"] is True and summary["observer_rms_error"] is None
    assert summary["triggers_mean"] == 20


def test_policy_plans_pass_dmpc_plans_and_hold_other_actions_in_the_box():
    from uav_formation_env.config_io import resolve_scenario
    from uav_formation_env.core.observation import ESTIMATE_SCALE, observation_dim
    from uav_formation_env.evaluation import policy_plans

    scenario = resolve_scenario("paper")
    n, horizon, u_max = scenario.n_uav, scenario.cost.horizon, scenario.dynamics.u_max
    obs = np.zeros((1, n, observation_dim(n)), dtype=np.float32)
    obs[0, 0, 9:12] = np.array([1.0, -2.0, 0.0]) / ESTIMATE_SCALE  # estimate of UAV 0 [m/s^2]
    actions = np.full((1, n, 3), 0.9)  # 4.5 m/s^2 on every axis
    plans = policy_plans(HeuristicPolicy(scenario), obs, actions, scenario)
    assert plans.shape == (1, n, horizon, 3)
    # UAV 0's box is |u| <= u_max - |estimate| = (4, 3, 5): the held action is clipped to it
    np.testing.assert_allclose(plans[0, 0], np.tile([4.0, 3.0, 4.5], (horizon, 1)))
    np.testing.assert_allclose(plans[0, 1:], 0.9 * u_max)

    class Broadcasting:
        plans = np.arange(n * horizon * 3, dtype=float).reshape(1, n, horizon, 3)

    np.testing.assert_array_equal(
        policy_plans(Broadcasting(), obs, actions, scenario), Broadcasting.plans
    )


def test_nash_gap_summary_counts_only_plans_in_the_box():
    from uav_formation_env.evaluation import nash_gap_summary

    batch = SimpleNamespace(
        nash_gap=np.array([[[1.0, 3.0]], [[-5.0, 2.0]]]),  # (T=2, B=1, N=2)
        nash_cost=np.array([[[10.0, 10.0]], [[10.0, 4.0]]]),
        nash_in_box=np.array([[[True, True]], [[False, True]]]),
    )
    s = nash_gap_summary(batch)
    assert s["median"] == 2.0 and s["mean"] == 2.0 and s["max"] == 3.0
    assert s["relative_median"] == pytest.approx(0.3)  # 0.1, 0.3, 0.5
    assert s["in_box_fraction"] == 0.75
    unmeasured = SimpleNamespace(nash_gap=None, nash_cost=None, nash_in_box=None)
    assert nash_gap_summary(unmeasured) is None
