"""RL baselines: hyper-parameters, the training stack, a PPO / SAC smoke run, saving, loading
through the package's evaluation, VecNormalize round trip, shipped models, and the comparison
table of the evaluate script (cost beside the mission metrics)."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip("stable_baselines3")
pytest.importorskip("torch")

from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.vec_env import VecNormalize  # noqa: E402

from uav_formation_baselines.callbacks import live_policy  # noqa: E402
from uav_formation_baselines.config import (  # noqa: E402
    TRAINING_DEFAULTS,
    load_hyperparams,
    parse_set,
    split_params,
)
from uav_formation_baselines.evaluate import (  # noqa: E402
    OUTPUT_FILES,
    compare,
    evaluate_run,
    format_markdown,
    format_table,
    run_scenario,
)
from uav_formation_baselines.evaluate import main as evaluate_main  # noqa: E402
from uav_formation_baselines.imitation import (  # noqa: E402
    ImitationConfig,
    load_config,
    teacher_scenario,
)
from uav_formation_baselines.plots import learning_curve  # noqa: E402
from uav_formation_baselines.train import main as train_main  # noqa: E402
from uav_formation_baselines.wrappers import (  # noqa: E402
    make_training_env,
    training_scenario,
)
from uav_formation_env.config_io import (  # noqa: E402
    load_scenario,
    resolve_scenario,
    save_scenario,
    with_overrides,
)
from uav_formation_env.envs.vector import FormationVecEnv  # noqa: E402
from uav_formation_env.episode import FormationEpisodes, observations_of  # noqa: E402
from uav_formation_env.evaluation import (  # noqa: E402
    SB3Policy,
    make_policy,
    run_episodes,
    summarise,
)
from uav_formation_env.policies.learned import ObsStats  # noqa: E402
from uav_formation_env.policies.registry import MODELS_DIR, SHIPPED_MODELS  # noqa: E402
from uav_formation_env.scenes import seeds_by_n_uav  # noqa: E402

SHORT_N3 = {"duration": 4.0}  # 20 control steps per episode


def short_scenario():
    return with_overrides(resolve_scenario("n3"), SHORT_N3)


@pytest.fixture(scope="module")
def scenario_yaml(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("scenario") / "n3_short.yaml"
    save_scenario(short_scenario(), path)
    return path


@pytest.fixture(scope="module")
def ppo_run(tmp_path_factory, scenario_yaml) -> Path:
    """A PPO run of 1920 agent-steps (2 copies x 3 UAVs x 32 steps x 10 rollouts)."""
    out = tmp_path_factory.mktemp("ppo_run")
    code = train_main(
        [
            "--algo", "ppo", "--timesteps", "1920", "--out", str(out),
            "--scenario", str(scenario_yaml), "--seed", "3", "--copies", "2", "--no-progress",
            "--set", "n_steps=32", "batch_size=64", "n_epochs=2", "learning_rate=1e-3",
            "eval_freq=576", "eval_seeds=[7]", "checkpoint_freq=960",
        ]
    )  # fmt: skip
    assert code == 0
    return out


# ------------------------------------------------------------------------- hyper-parameters
@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_hyperparams_load_for_every_scenario(algo):
    from uav_formation_baselines.train import algorithm_class

    for key in ("paper", "n8", "not_a_section"):
        params = load_hyperparams(algo, key)
        training, kwargs = split_params(params, algorithm_class(algo))
        assert set(training) == set(TRAINING_DEFAULTS)
        assert "gamma" in kwargs and "copies" not in kwargs
        assert isinstance(kwargs["policy_kwargs"]["activation_fn"], type)


def test_hyperparams_reject_a_section_that_names_no_scenario(tmp_path):
    path = tmp_path / "ppo.yml"
    path.write_text("default: {n_steps: 64}\nwindyy: {n_steps: 32}\n")
    with pytest.raises(ValueError, match="unknown section 'windyy'"):
        load_hyperparams("ppo", "windy", path)


def test_set_overrides_parse_yaml_and_reject_unknown_keys():
    patch = parse_set(["learning_rate=1e-3", "policy_kwargs.net_arch=[256, 256]", "copies=4"])
    assert patch == {"learning_rate": 1e-3, "policy_kwargs": {"net_arch": [256, 256]}, "copies": 4}
    with pytest.raises(ValueError, match="key=value"):
        parse_set(["learning_rate"])
    with pytest.raises(ValueError, match="learnin_rate"):
        split_params({**load_hyperparams("ppo", "paper"), "learnin_rate": 1.0}, PPO)


# ------------------------------------------------------------------------- training stack
def test_training_options_are_the_episode_layers():
    """The stack sets scenario.episode; the layer applies it (reward transform, divergence)."""
    training = {
        "copies": 2,
        "episode": {"reward": "log1p", "reward_scale": 100.0, "max_formation_error": 1e-3},
        "env_overrides": {"collision": {"mode": "penalty"}},
    }
    scenario = training_scenario(short_scenario(), training)
    assert scenario.episode.reward == "log1p" and scenario.collision.mode == "penalty"
    assert scenario.episode.max_velocity_error == 0.0  # untouched options keep their defaults
    venv = FormationVecEnv(scenario, 2)
    venv.seed(0)
    venv.reset()
    _, rewards, dones, infos = venv.step(np.zeros((venv.num_envs, 3)))
    cost = np.array([info["J"] for info in infos])
    np.testing.assert_allclose(rewards, -np.log1p(cost / 100.0), rtol=1e-5)
    # the random start box is > 1 mm off formation: every copy diverges and is truncated
    assert dones.all() and all(info["TimeLimit.truncated"] for info in infos)


def test_training_stack_from_defaults():
    from uav_formation_baselines.config import TRAINING_DEFAULTS

    training = {**TRAINING_DEFAULTS, "copies": 3}
    env, base = make_training_env(short_scenario(), training, gamma=0.99)
    assert isinstance(env, VecNormalize) and env.unwrapped is base and base.num_envs == 9
    env.seed(0)
    obs = env.reset()
    assert obs.shape == (9, base.observation_space.shape[0])
    assert base.sim.steps.tolist() == [0, 6, 13]  # staggered over the 20-step episode
    obs, rewards, _, _ = env.step(np.zeros((9, 3)))
    assert np.all(np.isfinite(obs)) and np.all(np.isfinite(rewards))


def test_vecnormalize_round_trip(tmp_path):
    venv = VecNormalize(FormationVecEnv(short_scenario(), 2), clip_obs=10.0)
    venv.seed(1)
    venv.reset()
    rng = np.random.default_rng(0)
    for _ in range(15):
        venv.step(rng.uniform(-1, 1, (venv.num_envs, 3)))
    raw = venv.get_original_obs()
    path = tmp_path / "vecnormalize.pkl"
    venv.save(str(path))
    loaded = VecNormalize.load(str(path), FormationVecEnv(short_scenario(), 2))
    ObsStats.of(venv).save(tmp_path / "obs_stats.npz")
    stats = ObsStats.load(tmp_path / "obs_stats.npz")  # as SB3Policy reads it: no pickle
    assert np.array_equal(loaded.normalize_obs(raw), venv.normalize_obs(raw))
    np.testing.assert_allclose(stats.normalize(raw), venv.normalize_obs(raw), rtol=1e-6)
    assert np.allclose(loaded.obs_rms.mean, venv.obs_rms.mean)


# ------------------------------------------------------------------------- PPO smoke run
def test_ppo_run_writes_every_output(ppo_run):
    for name in (
        "model.zip",
        "obs_stats.npz",
        "vecnormalize.pkl",
        "config.yaml",
        "scenario.yaml",
        "progress.csv",
    ):
        assert (ppo_run / name).is_file(), name
    assert any((ppo_run / "tensorboard").iterdir())
    assert (ppo_run / "best" / "model.zip").is_file()
    assert (ppo_run / "best" / "vecnormalize.pkl").is_file()
    assert (ppo_run / "best" / "obs_stats.npz").is_file()
    assert sorted(p.name for p in (ppo_run / "checkpoints").iterdir()) == [
        "000000960",
        "000001920",
    ]
    config = yaml.safe_load((ppo_run / "config.yaml").read_text())
    assert config["algo"] == "ppo" and config["seed"] == 3
    assert config["timesteps"] == 1920 and config["num_envs"] == 6
    assert config["hyperparams"]["n_steps"] == 32 and config["hyperparams"]["copies"] == 2
    assert config["wall_time_s"] > 0
    with open(ppo_run / "evaluations.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    assert [int(r["timesteps"]) for r in rows] == [576, 1152, 1728, 1920]
    assert all(math.isfinite(float(r["realised_cost_mean"])) for r in rows)


def test_ppo_learning_moves_the_policy(ppo_run):
    with open(ppo_run / "progress.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    trained = [r for r in rows if r.get("train/value_loss")]
    assert len(trained) >= 5
    assert all(math.isfinite(float(r["train/value_loss"])) for r in trained)
    assert all(float(r["train/approx_kl"]) > 0 for r in trained)  # the policy did change
    returns = [float(r["rollout/ep_rew_mean"]) for r in rows if r.get("rollout/ep_rew_mean")]
    assert returns and all(math.isfinite(x) and x < 0 for x in returns)
    model = PPO.load(ppo_run / "model.zip", device="cpu")
    log_std = model.policy.log_std.detach().numpy()
    assert not np.allclose(log_std, -1.0)  # moved from log_std_init


def test_trained_model_evaluates_through_the_package(ppo_run):
    scenario = run_scenario(ppo_run)
    assert scenario == short_scenario()
    policy = make_policy(str(ppo_run / "model.zip"), scenario)
    assert isinstance(policy, SB3Policy) and policy.algo == "PPO"
    assert policy.stats is not None  # read from obs_stats.npz: no pickle
    obs = observations_of(*_reset(scenario, seeds=[0, 1]))
    actions = policy.act_batch(obs)
    assert actions.shape == (2, 3, 3) and np.all(np.abs(actions) <= 1.0)
    # the training-time evaluation computes the same actions as the saved model's
    policy.model.set_env(_normalized_venv(ppo_run, policy, scenario))
    live = live_policy(policy.model)
    assert np.allclose(live.act_batch(obs), actions, atol=1e-6)
    summary = evaluate_run(ppo_run, seeds=[0, 1])
    assert summary["n_steps"] == 20 and math.isfinite(summary["realised_cost_mean"])
    results = compare([ppo_run], ["heuristic"], seeds=[0])
    assert set(results) == {str(ppo_run), "heuristic"}
    assert evaluate_run(ppo_run, seeds=[0], best=True)["n_steps"] == 20


def test_learning_curve_png(ppo_run, tmp_path):
    png = learning_curve([ppo_run], tmp_path / "curve.png", references={"heuristic": 1e4})
    assert png.is_file() and png.stat().st_size > 1000


def _reset(scenario, seeds):
    from uav_formation_env.sim import FormationSim

    sim = FormationSim(scenario, batch_size=len(seeds))
    return sim, sim.reset(seed=seeds)


# ------------------------------------------------------------------------- SAC smoke run
def test_sac_smoke_run(tmp_path, scenario_yaml):
    code = train_main(
        [
            "--algo", "sac", "--timesteps", "360", "--out", str(tmp_path), "--copies", "1",
            "--scenario", str(scenario_yaml), "--no-progress",
            "--set", "learning_starts=120", "batch_size=32", "eval_freq=0", "buffer_size=1000",
            "policy_kwargs.net_arch=[32,32]",
        ]
    )  # fmt: skip
    assert code == 0
    policy = make_policy(str(tmp_path / "model.zip"), short_scenario())
    assert policy.algo == "SAC"
    obs = observations_of(*_reset(short_scenario(), seeds=[0]))
    assert policy.act_batch(obs).shape == (1, 3, 3)


def test_a_velocity_mode_run_flies_through_its_set_point_loop(tmp_path, scenario_yaml):
    from uav_formation_env.policies.action_modes import VelocitySetpointPolicy

    code = train_main(
        [
            "--algo", "ppo", "--timesteps", "192", "--out", str(tmp_path), "--copies", "2",
            "--scenario", str(scenario_yaml), "--no-progress",
            "--set", "n_steps=32", "batch_size=64", "n_epochs=1", "eval_freq=96",
            "episode.reward=train", "episode.action=velocity", "episode.velocity_range=7.5",
            "env_overrides.observation.route_offset=true",
        ]
    )  # fmt: skip
    assert code == 0  # its evaluations fly the observation it trained on, in its action mode
    assert (tmp_path / "evaluations.csv").read_text().count("\n") == 3  # header + 2 rows
    trained = resolve_scenario(tmp_path / "scenario.yaml")
    assert trained.episode.action == "velocity" and trained.episode.reward == "train"
    assert trained.observation.route_offset
    policy = make_policy(str(tmp_path), run_scenario(tmp_path))
    assert isinstance(policy, VelocitySetpointPolicy)
    assert policy.velocity_range == 7.5


# ------------------------------------------------------------------------- shipped models
@pytest.mark.parametrize("name", sorted(SHIPPED_MODELS))
def test_shipped_models_fly_their_scenario(name):
    # the first 2 s of full-length episodes: a drawn scene fills the episode's duration, so a
    # shorter one would be another scene (or none: random_fields cannot place its field in 2 s)
    path = MODELS_DIR / name
    scenario = run_scenario(path)
    # two seeds that draw one N (a distribution over N, random_swarm, is flown one N at a time)
    n_uav, seeds = next(
        (n, group[:2]) for n, group in seeds_by_n_uav(scenario, range(40)).items() if len(group) > 1
    )
    episodes = FormationEpisodes(scenario, 2, n_uav=n_uav)
    policy = make_policy(name, scenario)
    teacher = _teacher_of(path, scenario)
    if hasattr(policy, "reset"):  # as the runner: stateful policies get one stream per seed
        policy.reset(2, seeds=seeds)
    step = episodes.reset(seed=seeds)
    actions, teacher_actions = [], []
    for _ in range(10):
        action = policy.act_batch(step.observation)
        assert action.shape == (2, n_uav, 3) and np.all(np.isfinite(action))
        assert np.all(np.abs(action) <= scenario.dynamics.u_max)
        actions.append(action)
        teacher_actions.append(teacher.act_batch(step.observation, **_plans_of(step, scenario)))
        step = episodes.step(action)
        # a clone of the reference holds the formation over the first seconds
        assert step.result.min_separation.min() > scenario.collision.uav_distance
    # ... and acts as the teacher it was cloned from would, on the states it flies into: the
    # shipped clones are at 0.31-0.60 of the teacher's action norm, a policy blind to its
    # observation (zeros in) at 1.0-1.96 (it flies the formation safely through 2 s all the same)
    if name.endswith("_dagger"):  # a clone; paper_ppo learned from the reward alone
        difference = np.linalg.norm(np.array(actions) - np.array(teacher_actions))
        assert difference / np.linalg.norm(teacher_actions) < 0.8


def _teacher_of(path: Path, scenario):
    """The reference a shipped DAgger clone learned from, planning with its training cost: the
    settings recorded with the model (one student's, or the recipe's), else the shipped bc.yml
    section of its scenario."""
    with open(path / "config.yaml", encoding="utf-8") as stream:
        record = yaml.safe_load(stream)
    settings = record.get("config") or record.get("recipe", {}).get("settings")
    config = (
        ImitationConfig.from_mapping(settings, where=str(path / "config.yaml"))
        if settings
        else load_config(record["scenario"])
    )
    return make_policy(config.teacher, teacher_scenario(scenario, config))


def _plans_of(step, scenario) -> dict:
    """The teacher's view of whose plans fill each neighbour slot (local observation only)."""
    return {"neighbour_index": step.neighbour_index} if scenario.observation.kind == "local" else {}


def _normalized_venv(run, policy, scenario):
    """The run's VecNormalize (its pickle, made by this test) around a fresh VecEnv, as during
    training."""
    venv = FormationVecEnv(scenario, policy.model.n_envs // scenario.n_uav)
    return VecNormalize.load(str(run / "vecnormalize.pkl"), venv)


# ------------------------------------------------------------------------- mission comparison
MISSION_HEADERS = (
    "realised J per UAV (mean ± 95% CI)",
    "vs LFPIO",
    "mission completed",
    "route error RMS [m]",
    "route error max [m]",
    "velocity RMSE [m/s]",
    "O1 met",
    "O2 met",
    "collisions after t = 0 (UAV-steps)",
    "min separation after t = 0 [m]",
)


def _markdown_cells(markdown: str) -> dict[str, dict[str, str]]:
    """{policy: {header: cell}} of the first markdown table in ``markdown``."""
    lines = [line for line in markdown.splitlines() if line.startswith("| ")]
    headers = [h.strip() for h in lines[0].strip("|").split("|")]
    table = {}
    for line in lines[1:]:
        cells = [c.strip() for c in line.strip("|").split("|")]
        table[cells[0]] = dict(zip(headers, cells))
    return table


@pytest.fixture(scope="module")
def small_comparison(tmp_path_factory):
    """``python -m uav_formation_baselines.evaluate`` on heuristic and random, 2 seeds, 20 s."""
    out = tmp_path_factory.mktemp("comparison")
    argv = ["--seeds", "2", "--duration", "20", "--compare", "heuristic", "random"]
    assert evaluate_main([*argv, "--out", str(out)]) == 0
    scenario = with_overrides(resolve_scenario("paper"), {"duration": 20.0})
    expected = {}
    for name in ("heuristic", "random"):
        batch = run_episodes(scenario, make_policy(name, scenario), [0, 1], policy_name=name)
        expected[name] = summarise(batch)
    return out, expected


def test_comparison_table_has_the_mission_columns():
    results = compare([], ["heuristic"], seeds=[0], scenario="paper", duration=4.0)
    text, markdown = format_table(results), format_markdown(results)
    for header in MISSION_HEADERS:
        assert header in text and header in markdown, header
    row = _markdown_cells(markdown)["heuristic"]
    assert row["vs LFPIO"] == "-"  # lfpio was not evaluated: no ratio
    assert set(MISSION_HEADERS) <= set(row)


def test_comparison_outputs_agree_with_summarise(small_comparison):
    out, expected = small_comparison
    for name in OUTPUT_FILES:
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    markdown = (out / "comparison.md").read_text(encoding="utf-8")
    assert "python -m uav_formation_baselines.evaluate --seeds 2 --duration 20" in markdown
    table = _markdown_cells(markdown)
    with open(out / "comparison.csv", newline="", encoding="utf-8") as stream:
        rows = {row["policy"]: row for row in csv.DictReader(stream)}
    summaries = yaml.safe_load((out / "summaries.json").read_text())  # JSON is YAML
    assert set(table) == set(rows) == set(summaries) == {"heuristic", "random"}
    for name, summary in expected.items():
        mission = summary["mission"]
        k, episodes = mission["completed"], mission["episodes"]
        assert episodes == 2
        assert table[name]["mission completed"] == f"{k}/{episodes}"
        assert int(rows[name]["completed"]) == k
        assert float(rows[name]["completion_rate"]) == pytest.approx(mission["completion_rate"])
        assert summaries[name]["mission"]["completed_per_seed"] == mission["completed_per_seed"]
        for key in ("route_error_rms_m", "route_error_max_m", "velocity_rmse_mps"):
            assert float(rows[name][key]) == pytest.approx(mission[key], rel=1e-5)
            assert float(rows[name][f"{key}_ci95"]) == pytest.approx(
                mission[f"{key}_ci95"], rel=1e-5, abs=1e-9
            )
        assert float(rows[name]["realised_cost_mean"]) == pytest.approx(
            summary["realised_cost_mean"], rel=1e-5
        )
        assert int(rows[name]["collisions_after_start"]) == mission["collisions_after_start"]
        assert table[name]["collisions after t = 0 (UAV-steps)"] == str(
            mission["collisions_after_start"]
        )
        for obstacle, stats in mission["obstacles"].items():
            assert table[name][f"{obstacle} met"].startswith(f"{stats['met']}/{episodes}")
            assert int(rows[name][f"{obstacle}_met"]) == stats["met"]
        failed = sorted(mission["failures"], key=int)
        assert rows[name]["failed_seeds"].split() == failed
        assert mission["completed"] == episodes - len(failed)
        for seed in failed:  # every failed seed is listed with its causes
            assert f"seed {seed}: {'; '.join(mission['failures'][seed])}" in markdown


def test_random_fields_local_yaml_is_random_fields_with_the_local_observation():
    # the scene file the RL baselines train on (baselines/RESULTS.md, "Reinforcement learning on
    # the scene distributions"): the registered random_fields with only the observation changed
    path = Path(__file__).parents[1] / "baselines" / "scenarios" / "random_fields_local.yaml"
    expected = with_overrides(resolve_scenario("random_fields"), {"observation": {"kind": "local"}})
    assert load_scenario(path) == expected
    assert load_scenario(path) != resolve_scenario("random_fields")


def test_learning_curves_take_sb3_evaluations_beside_dagger_rounds(tmp_path):
    from uav_formation_baselines.plots import run_curves, training_curves

    sb3, dagger = tmp_path / "ppo_s0", tmp_path / "dagger_s0"
    for run, algo in ((sb3, "algo: ppo"), (dagger, "algorithm: dagger")):
        run.mkdir()
        (run / "config.yaml").write_text(algo + "\n")
    (sb3 / "evaluations.csv").write_text(
        "timesteps,realised_cost_mean,collisions\n100000,2.5e6,0\n200000,1.5e6,3\n"
    )
    (dagger / "rounds.csv").write_text("round,samples,validation_cost\n0,1000,9e5\n")
    assert run_curves(sb3) == {"evaluation": [([1e5, 2e5], [2.5e6, 1.5e6])], "training": []}
    assert run_curves(dagger) == {"evaluation": [([1000.0], [9e5])], "training": []}
    png = training_curves([sb3, dagger], tmp_path / "curves.png", reference_cost=1e6)
    assert png.stat().st_size > 1000
