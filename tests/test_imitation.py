"""Behaviour cloning with DAgger (uav_formation_baselines.imitation) and the exported policy form
(uav_formation_baselines.torch_policy)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
import yaml

torch = pytest.importorskip("torch")

from uav_formation_baselines import HYPERPARAMS_DIR  # noqa: E402
from uav_formation_baselines.imitation import (  # noqa: E402
    ImitationConfig,
    best_round,
    collect,
    fit,
    load_config,
    main,
    resolve_device,
    sample_weights,
    teacher_scenario,
    train_imitation,
)
from uav_formation_baselines.imitation_data import (  # noqa: E402
    collect_in_workers,
    worker_pool,
)
from uav_formation_baselines.torch_policy import NormalisedMLP, save_policy  # noqa: E402
from uav_formation_env.config_io import resolve_scenario, with_overrides  # noqa: E402
from uav_formation_env.episode import FormationEpisodes  # noqa: E402
from uav_formation_env.policies import make_policy  # noqa: E402
from uav_formation_env.policies.dmpc import NashDMPCPolicy  # noqa: E402
from uav_formation_env.policies.shield import SafetyShield  # noqa: E402

SHORT = with_overrides(resolve_scenario("paper"), {"duration": 2.0})  # 10 steps


def tiny_config(**settings) -> ImitationConfig:
    """A DAgger run of seconds: 2 s episodes (10 steps), one epoch, an 8-unit layer."""
    return ImitationConfig(
        **{"epochs": 1, "validation_seeds": 1, "hidden": (8,), "duration": 2.0, **settings}
    )


class ZeroPolicy:
    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        return np.zeros((*obs.shape[:2], 3))


def test_config_rejects_unknown_and_bad_values(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown key 'epochz'"):
        ImitationConfig.from_mapping({"epochz": 3})
    with pytest.raises(ValueError, match="teacher must be one of"):
        ImitationConfig(teacher="ppo")
    with pytest.raises(ValueError, match="rounds must be an integer >= 1"):
        ImitationConfig(rounds=0)
    with pytest.raises(ValueError, match="beta must lie in"):
        ImitationConfig(beta=1.5)
    path = tmp_path / "bc.yml"
    path.write_text("default: {rounds: 2}\npaper: {episodes: 3}\n")
    config = load_config("paper", path, epochs=4)
    assert (config.rounds, config.episodes, config.epochs) == (2, 3, 4)
    assert load_config("paper").teacher == "exact"  # the shipped file loads
    path.write_text("default: {rounds: 2}\nrandom_feilds: {episodes: 3}\n")  # a misspelt section
    with pytest.raises(ValueError, match="unknown section 'random_feilds'"):
        load_config("random_fields", path)


@pytest.mark.parametrize("name", ["bc.yml", "bc_ensemble.yml"])
def test_every_section_of_the_shipped_files_configures_its_scenario(name: str) -> None:
    path = HYPERPARAMS_DIR / name
    table = yaml.safe_load(path.read_text())
    for section in table:
        config = load_config(section, path)  # valid values, merged over `default`
        for key, value in (table[section] or {}).items():
            expected = tuple(value) if isinstance(value, list) else value
            assert getattr(config, key) == expected, (section, key)


def test_teacher_rollout_labels_are_the_teachers_executed_actions() -> None:
    obs, labels, nearest, clearance = collect(SHORT, "exact", [3, 4])
    assert nearest.shape == clearance.shape == (10 * 2 * 5,)
    assert nearest.min() > 0
    assert obs.shape == (10 * 2 * 5, 47) and labels.shape == (10 * 2 * 5, 3)
    # the same teacher, flown on its own, sees the same observations and acts the same
    episodes = FormationEpisodes(SHORT, 2, fly_on_after_collision=True)
    teacher = NashDMPCPolicy(SHORT, "exact", threshold=0.0)
    teacher.reset(2, seeds=[3, 4])
    step = episodes.reset(seed=[3, 4])
    by_episode = [a.reshape(2, 10, 5, *a.shape[1:]) for a in (obs, labels, nearest, clearance)]
    for k in range(10):  # samples come episode by episode, then step, then UAV
        action = teacher.act_batch(step.observation)
        np.testing.assert_array_equal(by_episode[0][:, k], step.observation)
        np.testing.assert_allclose(by_episode[1][:, k], action, atol=1e-6)
        np.testing.assert_array_equal(by_episode[2][:, k], step.result.min_separation)
        np.testing.assert_array_equal(by_episode[3][:, k], step.result.obstacle_distance)
        step = episodes.step(action)


def test_learner_rollout_follows_the_learner_and_is_labelled_by_the_teacher() -> None:
    obs, labels, *_ = collect(SHORT, "exact", [3], learner=ZeroPolicy(), teacher_probability=0.0)
    episodes = FormationEpisodes(SHORT, 1, fly_on_after_collision=True)
    step = episodes.reset(seed=[3])
    for k in range(3):
        np.testing.assert_array_equal(obs[k * 5 : (k + 1) * 5], step.observation[0])
        step = episodes.step(np.zeros((1, 5, 3)))  # the learner's action was executed
    assert np.abs(labels).max() > 0.01  # labels are the teacher's, not the learner's zeros


class TowardsNeighbour:
    """Every UAV accelerates flat out at the UAV in its first slot (local layout)."""

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        towards = obs[..., 21:24].astype(float)  # slot 0's p_j - p_i, scaled
        return towards / np.maximum(np.linalg.norm(towards, axis=-1, keepdims=True), 1e-9)


def test_shielded_learner_rollout_visits_the_shielded_states() -> None:
    local = with_overrides(SHORT, {"observation": {"kind": "local"}})
    settings = {"learner": TowardsNeighbour(), "teacher_probability": 0.0}
    obs, labels, *_ = collect(local, "exact", [3], shield=True, **settings)
    plain_obs, plain_labels, *_ = collect(local, "exact", [3], **settings)
    shielded = SafetyShield(TowardsNeighbour(), local)
    episodes = FormationEpisodes(local, 1, fly_on_after_collision=True)
    step = episodes.reset(seed=[3])
    for k in range(10):
        np.testing.assert_array_equal(obs[k * 5 : (k + 1) * 5], step.observation[0])
        step = episodes.step(shielded.act_batch(step.observation))
    assert shielded.interventions > 0  # the shield acted, and the episode is not the plain one
    assert not np.array_equal(obs, plain_obs)
    assert np.abs(labels).max() > 0.01  # the teacher's labels, as without the shield
    with pytest.raises(ValueError, match="shield must be true or false"):
        tiny_config(shield="yes")


def test_teacher_cost_changes_the_teachers_labels_only() -> None:
    config = ImitationConfig(teacher_cost={"n": 40.0})  # the teacher tracks velocity harder
    planner = teacher_scenario(SHORT, config)
    assert planner.cost.n == 40.0 and SHORT.cost.n == 10.0
    assert teacher_scenario(SHORT, ImitationConfig()) is SHORT
    obs, labels, *_ = collect(SHORT, "exact", [3], teacher_scenario=planner)
    plain_obs, plain_labels, *_ = collect(SHORT, "exact", [3])
    # the first step's observation is the environment's either way; its label is the override's
    np.testing.assert_array_equal(obs[:5], plain_obs[:5])
    assert np.abs(labels[:5] - plain_labels[:5]).max() > 1e-3
    episodes = FormationEpisodes(SHORT, 1, fly_on_after_collision=True)
    teacher = NashDMPCPolicy(planner, "exact", threshold=0.0)
    teacher.reset(1, seeds=[3])
    step = episodes.reset(seed=[3])
    for k in range(10):
        action = teacher.act_batch(step.observation)
        np.testing.assert_allclose(labels[k * 5 : (k + 1) * 5], action[0], atol=1e-6)
        step = episodes.step(action)
    with pytest.raises(ValueError, match="teacher_cost must map cost fields"):
        ImitationConfig(teacher_cost={"obstacel": 100.0})


def test_masked_slot_is_never_seen_and_export_round_trips(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    sample = rng.normal(size=(32, 47)).astype(np.float32)
    model = NormalisedMLP(np.zeros(47), np.ones(47), (16,), "tanh", masked_slots=[12])
    changed = sample.copy()
    changed[:, 12] += 5.0
    with torch.no_grad():
        a, b = model(torch.as_tensor(sample)), model(torch.as_tensor(changed))
    torch.testing.assert_close(a, b, rtol=0, atol=0)
    changed[:, 11] += 5.0
    with torch.no_grad():
        assert not torch.equal(a, model(torch.as_tensor(changed)))
    path = save_policy(model, tmp_path / "policy", sample, observation="full")
    loaded = make_policy(str(path), SHORT)
    expected = np.clip(a[:, :3].numpy(), -1, 1).reshape(4, 8, 3)
    np.testing.assert_allclose(loaded.act_batch(sample.reshape(4, 8, 47)), expected, atol=1e-6)
    with pytest.raises(ValueError, match="masked_slots: slot 47"):
        NormalisedMLP(np.zeros(47), np.ones(47), masked_slots=[47])


def test_fit_learns_a_feedback_law() -> None:
    rng = np.random.default_rng(1)
    obs = rng.normal(size=(4000, 10)).astype(np.float32)
    target = np.tanh(obs[:, :3] - 0.5 * obs[:, 3:6]).astype(np.float32)
    model = NormalisedMLP(obs.mean(0), obs.std(0), (64,), "tanh")
    with torch.no_grad():
        before = float(
            torch.mean((model.mean_action(torch.as_tensor(obs)) - torch.as_tensor(target)) ** 2)
        )
    config = ImitationConfig(epochs=30, batch_size=256, learning_rate=3e-3)
    after = fit(model, obs, target, config, seed=0)
    assert after < before / 10


def test_sample_weights_mark_close_uavs_and_obstacles() -> None:
    nearest = np.array([5.0, 15.0, 15.0, 15.0, 15.0])  # d_s = 10 m
    clearance = np.array([50.0, 50.0, 3.0, np.inf, 50.0])
    config = ImitationConfig(proximity_weight=20.0, obstacle_margin=5.0)
    np.testing.assert_array_equal(
        sample_weights(nearest, clearance, SHORT, config), [20, 1, 20, 1, 1]
    )
    off = ImitationConfig(proximity_weight=20.0)  # margin 0: only UAVs count
    np.testing.assert_array_equal(sample_weights(nearest, clearance, SHORT, off), [20, 1, 1, 1, 1])


def test_fit_weights_decide_between_contradicting_labels() -> None:
    obs = np.zeros((2000, 4), dtype=np.float32)  # one state, two answers
    target = np.repeat(np.array([[0.5, 0, 0], [-0.5, 0, 0]], dtype=np.float32), 1000, axis=0)
    weights = np.repeat([9.0, 1.0], 1000)  # the weighted mean answer is 0.4
    model = NormalisedMLP(np.zeros(4), np.ones(4), (8,), "tanh")
    fit(
        model,
        obs,
        target,
        ImitationConfig(epochs=60, batch_size=500, learning_rate=1e-2),
        0,
        weights,
    )
    with torch.no_grad():
        answer = model.mean_action(torch.zeros(1, 4))[0, 0].item()
    assert answer == pytest.approx(0.4, abs=0.03)


def test_train_writes_a_loadable_policy(tmp_path: Path) -> None:
    config = tiny_config(rounds=2, episodes=1, masked_slots=(12,))
    record = train_imitation("paper", tmp_path, config, seed=0, progress=False)
    assert record["agent_steps"] == 2 * 10 * 5
    rows = (tmp_path / "rounds.csv").read_text().strip().splitlines()
    assert len(rows) == 3 and rows[0].startswith("round,samples,close_fraction,loss")
    policy = make_policy(str(tmp_path), SHORT)
    actions = policy.act_batch(np.zeros((1, 5, 47), dtype=np.float32))
    assert actions.shape == (1, 5, 3)


def test_cli_reports_bad_settings_in_one_line(tmp_path: Path, capsys) -> None:
    assert main(["--out", str(tmp_path), "--set", "rounds=0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: rounds must be an integer >= 1, got 0"]


def test_results_table_aggregates_runs_over_training_seeds(tmp_path: Path) -> None:
    import json

    from uav_formation_baselines.results import main as results_main

    config = tiny_config(rounds=1, episodes=1)
    runs = [tmp_path / f"run{seed}" for seed in (0, 1)]
    for seed, run in enumerate(runs):
        train_imitation("paper", run, config, seed=seed, progress=False)
    out = tmp_path / "table"
    argv = [*map(str, runs), "--seeds", "3", "--compare", "lfpio", "--out", str(out)]
    assert results_main(argv) == 0
    table = json.loads((out / "results.json").read_text())
    summaries = json.loads((out / "summaries.json").read_text())
    row, reference = table["rows"]
    assert row["policy"] == "dagger" and row["training_seeds"] == 2
    per_run = [summaries[str(run)]["realised_cost_mean"] for run in runs]
    half = 12.706 * np.std(per_run, ddof=1) / np.sqrt(2)  # Student t, 1 degree of freedom
    assert row["realised_cost_mean"] == pytest.approx(np.mean(per_run))
    assert row["realised_cost_mean_ci95"] == pytest.approx(half)
    assert row["episodes"] == 6
    assert row["completed"] == sum(summaries[str(r)]["mission"]["completed"] for r in runs)
    assert reference["policy"] == "lfpio" and reference["training_seeds"] is None
    assert reference["cost_ratio_to_reference"] == pytest.approx(1.0)
    assert (out / "learning_curves.png").stat().st_size > 1000
    assert (out / "results.md").read_text().count("\n| ") == 3  # header + 2 rows
    # one run of an algorithm (an ensemble, say): its interval over the evaluation seeds
    one = [str(runs[0]), "--seeds", "3", "--compare", "--out", str(tmp_path / "one")]
    assert results_main(one) == 0
    (single,) = json.loads((tmp_path / "one" / "results.json").read_text())["rows"]
    alone = json.loads((tmp_path / "one" / "summaries.json").read_text())[str(runs[0])]
    assert single["training_seeds"] == 1 and alone["realised_cost_ci95"] > 0
    assert single["realised_cost_mean_ci95"] == pytest.approx(alone["realised_cost_ci95"])


def test_cli_evaluate_flies_a_model_on_its_own_scenario(tmp_path: Path, capsys) -> None:
    from uav_formation_env.cli import main as cli_main

    config = tiny_config(rounds=1, episodes=1, overrides={"observation": {"kind": "local"}})
    train_imitation("paper", tmp_path / "run", config, progress=False)
    out = tmp_path / "eval"
    argv = ["evaluate", "--policy", str(tmp_path / "run"), "--seeds", "2", "--quiet"]
    assert cli_main([*argv, "--out", str(out)]) == 0
    assert "2 s episodes" in capsys.readouterr().out  # the run's scenario.yaml, not the paper's
    # another scenario (the paper's, full layout of 47 values) is flown through the model's own
    # 95-value local layout, as uav_formation_baselines.results does
    paper = [*argv, "--scenario", "paper", "--duration", "2", "--out", str(out), "--overwrite"]
    assert cli_main(paper) == 0
    assert "local observation" in capsys.readouterr().out
    # a full-layout model (its size depends on N) cannot fly another N: one error line
    config = tiny_config(rounds=1, episodes=1)
    train_imitation("paper", tmp_path / "full", config, progress=False)
    other_n = ["evaluate", "--policy", str(tmp_path / "full"), "--scenario", "n3", "--quiet"]
    assert cli_main([*other_n, "--seeds", "1", "--duration", "2", "--out", str(out)]) != 0
    assert "47" in capsys.readouterr().err


def test_start_episodes_add_short_episodes_of_their_own_seeds(tmp_path: Path) -> None:
    config = tiny_config(rounds=1, episodes=1, start_episodes=2, start_duration=0.4)
    record = train_imitation("paper", tmp_path, config, progress=False)
    assert record["agent_steps"] == (10 + 2 * 2) * 5  # one 10-step and two 2-step episodes
    with pytest.raises(ValueError, match="start_episodes must be an integer >= 0"):
        ImitationConfig(start_episodes=-1)


def test_results_fly_each_model_through_its_own_observation_layout(tmp_path: Path) -> None:
    from uav_formation_baselines.results import main as results_main

    config = tiny_config(rounds=1, episodes=1, overrides={"observation": {"kind": "local"}})
    train_imitation("paper", tmp_path / "run", config, progress=False)
    scenario = tmp_path / "paper_2s.yaml"  # the paper's physics and its full layout
    from uav_formation_env.config_io import save_scenario

    save_scenario(SHORT, scenario)
    argv = [str(tmp_path / "run"), "--scenario", str(scenario), "--seeds", "1", "--compare"]
    assert results_main([*argv, "--out", str(tmp_path / "out")]) == 0  # 95 values, not 47


def test_best_round_prefers_completed_missions_then_the_lower_cost() -> None:
    rows = [
        {"round": 0, "validation_completed": 3, "validation_cost": 1.0},
        {"round": 1, "validation_completed": 4, "validation_cost": 9.0},
        {"round": 2, "validation_completed": 4, "validation_cost": 5.0},
    ]
    assert best_round(rows)["round"] == 2
    assert best_round(rows[:2])["round"] == 1  # one more mission outweighs any cost


def test_select_round_chooses_again_on_more_validation_seeds(tmp_path: Path, capsys) -> None:
    config = tiny_config(rounds=2, episodes=1, validation_seeds=1)
    train_imitation("paper", tmp_path, config, progress=False)
    (tmp_path / "policy.npz").write_bytes(b"stale")  # whatever training kept is replaced
    assert main(["--out", str(tmp_path), "--select", "3"]) == 0
    assert "validation missions" in capsys.readouterr().out
    with open(tmp_path / "selection.csv", encoding="utf-8") as stream:
        rows = list(csv.DictReader(stream))
    assert [int(row["round"]) for row in rows] == [0, 1]
    assert {int(row["validation_episodes"]) for row in rows} == {3}
    scored = [
        {
            "round": int(r["round"]),
            "validation_completed": int(r["validation_completed"]),
            "validation_cost": float(r["validation_cost"]),
        }
        for r in rows
    ]
    chosen = best_round(scored)["round"]
    for name in ("policy.json", "policy.npz"):
        kept = (tmp_path / "rounds" / str(chosen) / name).read_bytes()
        assert (tmp_path / name).read_bytes() == kept
    record = yaml.safe_load((tmp_path / "config.yaml").read_text())
    assert record["best_round"] == chosen
    assert record["selection"] == {
        "validation_seed_start": 5000,
        "validation_seeds": 3,
        "round": chosen,
    }
    # the same scores with the validation episodes split over two worker processes
    assert main(["--out", str(tmp_path), "--select", "3", "--workers", "2"]) == 0
    with open(tmp_path / "selection.csv", encoding="utf-8") as stream:
        split = list(csv.DictReader(stream))
    assert [r["validation_completed"] for r in split] == [r["validation_completed"] for r in rows]
    np.testing.assert_allclose(
        [float(r["validation_cost"]) for r in split],
        [float(r["validation_cost"]) for r in rows],
        rtol=1e-6,
    )
    # a directory that is not a finished run: one line, nothing written
    assert main(["--out", str(tmp_path / "none"), "--select", "3"]) == 2
    assert capsys.readouterr().err.startswith("error: ")
    assert not (tmp_path / "none").exists()


def test_an_episode_is_named_by_its_seed_whatever_the_batch_or_the_workers(tmp_path: Path) -> None:
    model = NormalisedMLP(np.zeros(47), np.ones(47), (8,), "tanh")
    sample = np.zeros((4, 47), np.float32)
    learner = str(save_policy(model, tmp_path / "learner", sample, observation="full"))
    settings = {
        "scenario": SHORT,
        "teacher_name": "exact",
        "learner": learner,
        "teacher_probability": 0.5,  # each episode mixes teacher and learner by its own coins
        "mix_seed": 7,
    }
    together = collect(seeds=[3, 4, 5], **settings)
    alone = collect(seeds=[4], **settings)
    # seed 4's rows are the second 10 steps x 5 UAVs; equal up to the float32 rounding of the
    # learner's batched matrix products, which depends on the batch size
    for whole, single in zip(together, alone):
        np.testing.assert_allclose(whole[50:100], single, rtol=1e-5, atol=1e-6)
    pool = worker_pool(2)
    try:
        split = collect_in_workers(pool, 2, [3, 4, 5], **settings)
    finally:
        pool.shutdown()
    for whole, parts in zip(together, split):
        np.testing.assert_allclose(whole, parts, rtol=1e-5, atol=1e-6)
    # the coins were really flipped: the learner and the teacher both flew some steps
    assert not np.array_equal(
        together[0], collect(seeds=[3, 4, 5], **{**settings, "mix_seed": 8})[0]
    )
    with pytest.raises(ValueError, match="workers must be an integer >= 1, got 0"):
        worker_pool(0)


def test_fit_device_is_checked_and_the_cli_reports_bad_workers(tmp_path: Path, capsys) -> None:
    assert resolve_device("cpu") == "cpu"
    assert resolve_device("auto") == ("cuda" if torch.cuda.is_available() else "cpu")
    with pytest.raises(ValueError, match="device must be 'auto', 'cpu' or 'cuda"):
        resolve_device("tpu")
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="torch sees no CUDA device"):
            resolve_device("cuda")
    assert main(["--out", str(tmp_path / "run"), "--workers", "0"]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "error: workers must be an integer >= 1, got 0"
    ]
    assert not (tmp_path / "run").exists()  # nothing written before the settings were checked
