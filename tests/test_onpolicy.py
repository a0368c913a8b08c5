"""The on-policy trainer: GAE by hand, truncation bootstrap in a rollout, the policy-file export,
tiny runs of each algorithm, configuration errors."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from uav_formation_baselines.onpolicy import main
from uav_formation_baselines.onpolicy_config import OnPolicyConfig, load_config
from uav_formation_baselines.onpolicy_io import export_policy
from uav_formation_baselines.onpolicy_nets import ActorCritic, TorchActorPolicy
from uav_formation_baselines.onpolicy_trainer import (
    OnPolicyTrainer,
    bootstrap_truncated,
    build_scenario,
    gae,
)
from uav_formation_env.config_io import load_scenario, resolve_scenario, with_overrides
from uav_formation_env.policies.policy_file import load_policy_file, save_policy_file

TINY = {
    "copies": 4,
    "rollout_steps": 4,
    "epochs": 1,
    "minibatches": 2,
    "eval_seeds": 1,
    "hidden": [16, 16],
    "env": {"duration": 2.0},  # 20-step episodes: evaluation stays short
}


def test_gae_hand_computed_with_truncated_and_terminated_steps():
    # one copy, one agent, gamma 0.9, lambda 0.8: step 0 truncated with V(final) = 10
    # (bootstrapped), step 1 goes on, step 2 terminated (no value after it)
    gamma, lam = 0.9, 0.8
    raw = torch.tensor([[[1.0]], [[2.0]], [[3.0]]])
    final_value = torch.tensor([[10.0]])
    rewards = raw.clone()
    rewards[0] = bootstrap_truncated(raw[0], final_value, torch.tensor([True]), gamma)
    rewards[2] = bootstrap_truncated(raw[2], final_value, torch.tensor([False]), gamma)
    values = torch.tensor([[[0.5]], [[0.4]], [[0.3]]])
    dones = torch.tensor([[[1.0]], [[0.0]], [[1.0]]])
    advantages, returns = gae(rewards, values, dones, torch.tensor([[0.2]]), gamma, lam)
    # t=2: 3 - 0.3 = 2.7;  t=1: 2 + 0.9*0.3 - 0.4 = 1.87, + 0.72*2.7 = 3.814;
    # t=0: 1 + 0.9*10 - 0.5 = 9.5 (the next step belongs to a new episode)
    np.testing.assert_allclose(advantages.flatten(), [9.5, 3.814, 2.7], rtol=1e-6)
    np.testing.assert_allclose(returns.flatten(), [10.0, 4.214, 3.0], rtol=1e-6)


def test_rollout_bootstraps_the_truncated_step(tmp_path: Path):
    # 3-step episodes, a critic that says 5 everywhere: the reward stored at the last step of
    # each episode is the env's reward + gamma * 5, every other one the env's reward
    env = {"duration": 0.6, "episode": {"start": "zero"}}  # every copy's episode at once
    config = load_config("ppo", {**TINY, "env": env})
    trainer = OnPolicyTrainer("ppo", build_scenario("paper", config), config, 0, 1, tmp_path)
    last = trainer.model.critic.linears()[-1]
    with torch.no_grad():
        last.weight.zero_()
        last.bias.fill_(5.0)
    seen, step = [], trainer.episodes.step

    def recording(actions):
        result = step(actions)
        seen.append((np.array(result.reward), np.array(result.truncated)))
        return result

    trainer.episodes.step = recording
    trainer.rollout()
    for t, (reward, truncated) in enumerate(seen):
        assert truncated.all() == (t == 2)
        expected = reward + (config.gamma * 5.0 if t == 2 else 0.0)
        np.testing.assert_allclose(trainer.buf_rew[t].numpy(), expected, rtol=1e-5)
    np.testing.assert_array_equal(trainer.buf_done[:, 0].numpy(), [0, 0, 1, 0])


def _numpy_actor(directory: Path, obs: np.ndarray) -> np.ndarray:
    """The policy-file format's forward pass, written from its specification."""
    header = json.loads((directory / "policy.json").read_text())
    arrays = np.load(directory / "policy.npz", allow_pickle=False)
    x = (obs - arrays["obs_mean"]) / arrays["obs_std"]
    x = np.clip(x, -header["observation_clip"], header["observation_clip"])
    for layer in range(header["layers"]):
        w, b = arrays[f"m0.w{layer}"], arrays[f"m0.b{layer}"]
        # one network per agent: (N, out, in)
        x = np.einsum("...ni,noi->...no", x, w) + b if w.ndim == 3 else x @ w.T + b
        if layer < header["layers"] - 1:
            x = np.tanh(x)
    return np.clip(x, -1.0, 1.0)


@pytest.mark.parametrize("algo", ["ppo", "ippo"])
def test_export_round_trips(tmp_path: Path, algo: str):
    torch.manual_seed(0)
    model = ActorCritic(algo, 7, 3, 1, (16, 8), "tanh", -1.0, 3.0)
    model.obs_norm.update(torch.randn(500, 7) * 4 + 2)
    with torch.no_grad():  # a last layer large enough for the clip to act on some actions
        model.actor.linears()[-1].weight.mul_(300.0)
    obs = np.random.default_rng(0).normal(2, 8, (5, 3, 7)).astype(np.float32)
    export_policy(tmp_path, model, resolve_scenario("paper"), {"algorithm": algo})
    header = json.loads((tmp_path / "policy.json").read_text())
    assert header["format"] == "uav-formation-policy" and header["layers"] == 3
    expected = TorchActorPolicy(model).act_batch(obs)
    assert (np.abs(expected) == 1.0).any() and (np.abs(expected) < 1.0).any()
    np.testing.assert_allclose(_numpy_actor(tmp_path, obs), expected, atol=1e-5)
    np.testing.assert_allclose(load_policy_file(tmp_path).act_batch(obs), expected, atol=1e-5)


def test_a_per_agent_file_flies_only_its_number_of_uavs(tmp_path: Path):
    model = ActorCritic("ippo", 7, 3, 1, (16, 8), "tanh", -1.0, 3.0)
    export_policy(tmp_path, model, resolve_scenario("paper"), {"algorithm": "ippo"})
    policy = load_policy_file(tmp_path)
    assert policy.agents == 3
    with pytest.raises(ValueError, match="one network per UAV for 3 UAVs, got observations of 5"):
        policy.act_batch(np.zeros((2, 5, 7)))
    with pytest.raises(ValueError, match="needs a shared policy"):
        policy.act_flat(np.zeros((2, 7)))
    with pytest.raises(ValueError, match="needs a shared policy"):
        policy.parts()
    assert policy.act_batch(np.zeros((2, 3, 7))).shape == (2, 3, 3)


@pytest.mark.parametrize("algo", ["ppo", "mappo", "ippo"])
def test_tiny_run_writes_a_loadable_run_dir(tmp_path: Path, algo: str):
    config = load_config(algo, TINY)
    scenario = build_scenario("paper", config)
    frames = 2 * config.rollout_steps * config.copies * scenario.n_uav
    trainer = OnPolicyTrainer(algo, scenario, config, 0, frames, tmp_path / "run")
    result = trainer.train(progress=False)
    run = tmp_path / "run"
    assert result["frames"] == frames and result["eval_episodes"] == 1
    with open(run / "progress.csv", encoding="utf-8") as stream:
        rows = list(csv.DictReader(stream))
    assert [int(r["frames"]) for r in rows] == [frames // 2, frames]
    assert rows[-1]["eval_completed"] in ("0", "1") and rows[0]["eval_completed"] == ""
    saved = yaml.safe_load((run / "config.yaml").read_text())
    assert saved["algorithm"] == algo and saved["init"] == "" and saved["frames"] == frames
    assert saved["hyperparams"]["hidden"] == [16, 16]
    header = json.loads((run / "policy.json").read_text())
    assert header["algorithm"] == algo and header["scenario"] == "paper"
    assert header["training_reward"] == scenario.episode.reward
    state = torch.load(run / "checkpoint.pt", weights_only=True)
    assert state["frames"] == frames
    obs = np.asarray(trainer.episodes.observe())
    np.testing.assert_allclose(
        _numpy_actor(run, obs), TorchActorPolicy(trainer.model).act_batch(obs), atol=1e-5
    )
    # a fine-tuning run starts from the saved actor, critic and normalisers
    regularised = load_config(algo, {**TINY, "init_reg": 0.1})
    again = OnPolicyTrainer(algo, scenario, regularised, 1, frames, tmp_path / "ft", init=run)
    for key, value in trainer.model.state_dict().items():
        torch.testing.assert_close(again.model.state_dict()[key], value)
    # ... or from the policy files alone: the actor (architecture included) and its statistics
    files = tmp_path / "files"
    files.mkdir()
    for name in ("policy.json", "policy.npz"):
        shutil.copy(run / name, files / name)
    wide = load_config(algo, {**TINY, "hidden": [32]})
    adopted = OnPolicyTrainer(algo, scenario, wide, 1, frames, tmp_path / "ft2", init=files)
    assert adopted.config.hidden == (16, 16)
    np.testing.assert_allclose(
        TorchActorPolicy(adopted.model).act_batch(obs),
        TorchActorPolicy(trainer.model).act_batch(obs),
        atol=1e-5,
    )


def test_cli_runs_and_rejects_bad_input(tmp_path: Path, capsys):
    out = tmp_path / "cli"
    args = ["--algo", "mappo", "--task", "paper", "--frames", "80", "--out", str(out)]
    tiny = ["copies=4", "rollout_steps=4", "hidden=[8]", "env.duration=1.0", "eval_seeds=1"]
    assert main([*args, "--no-progress", "--set", *tiny]) == 0
    assert (out / "policy.npz").is_file() and "agent-steps/s" in capsys.readouterr().out
    assert main([*args, "--set", "learning_rat=1e-3"]) == 2
    assert "learning_rat" in capsys.readouterr().err


def test_config_rejects_unknown_keys_and_bad_values():
    with pytest.raises(ValueError, match="'learning_rat'"):
        load_config("ppo", {"learning_rat": 1e-3})
    with pytest.raises(ValueError, match="gamma"):
        OnPolicyConfig(gamma=1.5)
    with pytest.raises(ValueError, match="hidden"):
        OnPolicyConfig(hidden=[64, 0])
    with pytest.raises(ValueError, match=r"promote_route_error must be a number >= 0 \[m\]"):
        OnPolicyConfig(promote_route_error=-1.0)
    with pytest.raises(ValueError, match="unknown scenario key 'episode.rewrd'"):
        build_scenario("paper", OnPolicyConfig(env={"episode": {"rewrd": "raw"}}))


@pytest.mark.parametrize("algo", ["ippo", "mappo"])
def test_per_uav_networks_and_the_state_critic_refuse_a_scenario_of_varying_n(
    tmp_path: Path, algo: str
):
    config = load_config(algo, TINY)
    with pytest.raises(ValueError, match=f"{algo} needs a fixed number of UAVs"):
        OnPolicyTrainer(algo, resolve_scenario("random_swarm"), config, 0, 1, tmp_path)


def test_ppo_trains_a_distribution_over_n_one_group_of_copies_per_n(tmp_path: Path):
    """random_swarm draws N in 3..10: PPO steps one group of copies per N in turn, an update
    each, every group's episodes of its own N (each update's frames are T B N of its group)."""
    scenario = with_overrides(resolve_scenario("random_swarm"), {"scene.n_uav": [3, 5]})
    config = load_config("ppo", {**TINY, "eval_every": 0})
    T, B = config.rollout_steps, config.copies
    frames = T * B * (3 + 4 + 5 + 3)  # four updates: N = 3, 4, 5, then 3 again
    trainer = OnPolicyTrainer("ppo", scenario, config, 0, frames, tmp_path)
    assert [group["episodes"].n_uav for group in trainer.groups] == [3, 4, 5]
    seen = []
    for update in range(4):
        trainer._activate(update % len(trainer.groups))
        trainer.rollout()
        seen.append(tuple(trainer.buf_obs.shape[:3]))
        assert all(scene.n_uav == trainer.episodes.n_uav for scene in trainer.episodes.sim.scenes)
        trainer.update()
    assert seen == [(T, B, 3), (T, B, 4), (T, B, 5), (T, B, 3)]
    assert trainer.frames == frames
    # the paused group goes on from where it stopped, not from a reset
    assert int(trainer.groups[1]["episodes"].sim.steps.min()) == T


def test_torch_backend_steps_the_same_rules(tmp_path: Path):
    # the torch episode layer (what --device cuda runs) on the CPU: tensors end to end,
    # truncations every 3 steps bootstrapped from the final observations' values
    config = load_config("mappo", {**TINY, "env": {"duration": 0.6}, "eval_every": 0})
    scenario = build_scenario("paper", config)
    frames = 2 * config.rollout_steps * config.copies * scenario.n_uav
    trainer = OnPolicyTrainer("mappo", scenario, config, 0, frames, tmp_path, backend="torch")
    result = trainer.train(progress=False)
    assert torch.is_tensor(trainer.episodes.observe()) and result["frames"] == frames
    # the second rollout's steps 2, 3 of an episode then 1, 2 of the next: one end, at index 1
    assert torch.isfinite(trainer.buf_rew).all()
    np.testing.assert_array_equal(trainer.buf_done[:, 0].numpy(), [0, 1, 0, 0])


def test_a_shared_policy_starts_every_ippo_agent(tmp_path: Path):
    config = load_config("ippo", TINY)
    scenario = build_scenario("paper", config)
    shared = OnPolicyTrainer("ppo", scenario, load_config("ppo", TINY), 0, 1, tmp_path / "ppo")
    with torch.no_grad():
        shared.model.actor.linears()[-1].weight.normal_()  # actions far from zero
    export_policy(tmp_path / "ppo", shared.model, scenario, {"algorithm": "ppo"})
    ippo = OnPolicyTrainer("ippo", scenario, config, 0, 1, tmp_path / "ippo", init=tmp_path / "ppo")
    obs = np.asarray(shared.episodes.observe())
    expected = TorchActorPolicy(shared.model).act_batch(obs)
    assert np.abs(expected).mean() > 0.05
    np.testing.assert_allclose(TorchActorPolicy(ippo.model).act_batch(obs), expected, atol=1e-5)
    with pytest.raises(ValueError, match="init_reg"):
        OnPolicyTrainer(
            "ppo", scenario, load_config("ppo", {**TINY, "init_reg": 1.0}), 0, 1, tmp_path
        )


def test_an_interrupted_run_saves_what_it_has(tmp_path: Path):
    config = load_config("ppo", {**TINY, "eval_every": 0})
    scenario = build_scenario("paper", config)
    trainer = OnPolicyTrainer("ppo", scenario, config, 0, 10**6, tmp_path)
    update = trainer.update

    def interrupted():
        if trainer.update_index == 2:
            raise KeyboardInterrupt
        return update()

    trainer.update = interrupted
    result = trainer.train(progress=False)
    frames = 2 * config.rollout_steps * config.copies * scenario.n_uav  # the updates done
    assert result["frames"] == frames and "eval_completed" not in result
    assert json.loads((tmp_path / "policy.json").read_text())["frames"] == frames
    assert torch.load(tmp_path / "checkpoint.pt", weights_only=True)["update"] == 2


def test_resume_continues_the_run(tmp_path: Path):
    config = load_config("mappo", {**TINY, "eval_every": 0})
    scenario = build_scenario("paper", config)
    per_update = config.rollout_steps * config.copies * scenario.n_uav
    OnPolicyTrainer("mappo", scenario, config, 0, 2 * per_update, tmp_path).train(progress=False)
    saved = torch.load(tmp_path / "checkpoint.pt", weights_only=True)
    again = OnPolicyTrainer("mappo", scenario, config, 0, 4 * per_update, tmp_path, resume=True)
    assert again.update_index == 2 and again.frames == 2 * per_update
    for key, value in saved["model"].items():
        torch.testing.assert_close(again.model.state_dict()[key], value)
    assert (
        again.optimizer.state_dict()["state"][0]["step"] == saved["optimizer"]["state"][0]["step"]
    )
    again.train(progress=False)
    with open(tmp_path / "progress.csv", encoding="utf-8") as stream:
        rows = list(csv.DictReader(stream))
    assert [int(r["update"]) for r in rows] == [1, 2, 3, 4]
    assert float(rows[3]["wall_s"]) >= float(rows[1]["wall_s"])
    assert torch.load(tmp_path / "checkpoint.pt", weights_only=True)["frames"] == 4 * per_update


@pytest.mark.parametrize("bootstrap_diverged", [True, False])
def test_diverged_copies_bootstrap_only_if_asked(tmp_path: Path, bootstrap_diverged: bool):
    # full thrust against a 0.5 m/s velocity bound: every copy diverges at every step
    overrides = {"env": {"episode": {"max_velocity_error": 0.5}}}
    overrides["bootstrap_diverged"] = bootstrap_diverged
    config = load_config("ppo", {**TINY, **overrides})
    trainer = OnPolicyTrainer("ppo", build_scenario("paper", config), config, 0, 1, tmp_path)
    with torch.no_grad():
        for network, value in ((trainer.model.actor, 10.0), (trainer.model.critic, 5.0)):
            network.linears()[-1].weight.zero_()
            network.linears()[-1].bias.fill_(value)
    rewards, step = [], trainer.episodes.step

    def recording(actions):
        result = step(actions)
        assert result.diverged.all() and result.truncated.all()
        rewards.append(np.array(result.reward))
        return result

    trainer.episodes.step = recording
    trainer.rollout()
    bonus = config.gamma * 5.0 if bootstrap_diverged else 0.0
    np.testing.assert_allclose(trainer.buf_rew.numpy(), np.stack(rewards) + bonus, rtol=1e-5)


def test_curriculum_moves_up_after_a_completed_evaluation(tmp_path: Path) -> None:
    config = load_config(
        "ppo",
        {
            "copies": 2,
            "rollout_steps": 4,
            "epochs": 1,
            "minibatches": 1,
            "eval_seeds": 1,
            "promote_at": 0.0,
        },
    )
    hold, track = (build_scenario(t, config) for t in ("hold", "track"))
    short = [with_overrides(s, {"duration": 20.0}) for s in (hold, track)]
    trainer = OnPolicyTrainer("ppo", short[0], config, 0, 1, tmp_path, ladder=[short[1]])
    assert trainer.scenario.name == "hold" and not trainer.promote()  # no evaluation yet
    trainer.evaluate()
    assert trainer.promote() and trainer.scenario.name == "track"
    trainer.save()  # evaluation flies a run on its scenario.yaml: the task it ended on
    assert load_scenario(tmp_path / "scenario.yaml").name == "track"
    assert trainer.episodes.scenario.name == "track" and trainer.metadata()["curriculum"] == [
        "hold",
        "track",
    ]
    trainer.evaluate()
    assert not trainer.promote()  # the last task
    with pytest.raises(ValueError, match="one observation size"):
        OnPolicyTrainer("ppo", hold, config, 0, 1, tmp_path, ladder=[build_scenario("n3", config)])


def _hold_then_track(config: OnPolicyConfig, tmp_path: Path) -> OnPolicyTrainer:
    """A PPO trainer on a 20 s ``hold`` whose curriculum goes on to a 20 s ``track``."""
    hold, track = (build_scenario(t, config) for t in ("hold", "track"))
    short = [with_overrides(s, {"duration": 20.0}) for s in (hold, track)]
    return OnPolicyTrainer("ppo", short[0], config, 0, 1, tmp_path, ladder=[short[1]])


def test_curriculum_waits_for_the_route_error_bound(tmp_path: Path) -> None:
    config = load_config("ppo", {**TINY, "copies": 2, "promote_route_error": 80.0})
    trainer = _hold_then_track(config, tmp_path)

    def evaluated(completed: int, route_error_max: float) -> bool:
        trainer.last_eval = {
            "eval_completed": completed,
            "eval_episodes": 4,
            "eval_route_error_max_m": route_error_max,
        }
        return trainer.promote()

    assert not evaluated(4, 80.5)  # every mission completed, but too far from the route
    assert not evaluated(4, float("nan"))
    assert not evaluated(2, 10.0)  # on the route, but under promote_at (0.75) of the missions
    assert trainer.scenario.name == "hold"
    assert evaluated(3, 80.0) and trainer.scenario.name == "track"


def test_no_route_error_bound_promotes_on_completion_alone(tmp_path: Path) -> None:
    config = load_config("ppo", {**TINY, "copies": 2, "promote_route_error": 0.0})
    trainer = _hold_then_track(config, tmp_path)
    trainer.last_eval = {"eval_completed": 3, "eval_episodes": 4, "eval_route_error_max_m": 500.0}
    assert trainer.promote() and trainer.scenario.name == "track"


def test_the_best_evaluation_on_the_last_task_is_kept_as_a_policy(tmp_path: Path) -> None:
    config = load_config("ppo", {**TINY, "copies": 2, "promote_at": 0.0})
    trainer = _hold_then_track(config, tmp_path)
    best = tmp_path / "best"

    def evaluated(completed: int, collisions: int, cost: float) -> bool:
        trainer.last_eval = {
            "task": trainer.scenario.name,
            "eval_completed": completed,
            "eval_episodes": 2,
            "eval_collisions": collisions,
            "eval_J": cost,
            "eval_route_error_max_m": 50.0,
        }
        return trainer.keep_best()

    assert not evaluated(2, 0, 1.0) and not best.exists()  # not the curriculum's last task
    assert trainer.promote() and trainer.scenario.name == "track"
    assert evaluated(1, 3, 5.0)
    assert not evaluated(1, 4, 1.0)  # fewer completed missions or more collisions lose ...
    assert not evaluated(0, 0, 1.0)
    assert not evaluated(1, 3, 5.0)  # ... and a tie keeps the earlier policy
    assert evaluated(1, 3, 4.0)  # then the lower J wins
    assert evaluated(2, 9, 9.0)  # completion first
    header = json.loads((best / "policy.json").read_text())
    assert header["selected_by"]["eval_completed"] == 2 and header["scenario"] == "track"
    assert load_scenario(best / "scenario.yaml").name == "track"
    assert yaml.safe_load((best / "config.yaml").read_text())["algorithm"] == "ppo"
    load_policy_file(best)  # a policy directory evaluate --policy flies
    trainer.save()  # a resumed run remembers what it has to beat
    again = OnPolicyTrainer("ppo", trainer.scenario, config, 0, 1, tmp_path, resume=True)
    assert again.best == [2, -9, -9.0]


def test_results_rows_are_configurations_not_seeds():
    from uav_formation_baselines.results import configuration_label

    plain = {"algorithm": "ppo", "hyperparams": {"env": {}}, "init": ""}
    assert configuration_label(plain) == "ppo"
    variant = {
        "algorithm": "ppo",
        "hyperparams": {"env": {"episode": {"train": {"separation": 0.3, "route": 0}}}},
        "init": "/runs/random_fields_dagger_m0",
    }
    assert configuration_label(variant) == (
        "ppo (episode.train.separation=0.3, episode.train.route=0) from random_fields_dagger_m0"
    )
    assert configuration_label({"algorithm": "mappo"}) == "mappo"  # other recipes' configs
    shipped = load_config("ppo").as_dict()
    tuned = {"algorithm": "ppo", "hyperparams": {**shipped, "ent_coef": 0.01, "threads": 2}}
    assert configuration_label(tuned) == "ppo (ent_coef=0.01)"  # threads do not change a run
    sb3 = {"algorithm": "sac", "hyperparams": {"ent_coef": "auto"}}
    assert configuration_label(sb3) == "sac"  # only the in-process trainer's settings
    best = {**plain, "selected_by": {"eval_completed": 20}}
    assert configuration_label(best) == "ppo, best validation"


def test_results_name_a_missing_run_in_one_line(tmp_path: Path, capsys) -> None:
    from uav_formation_baselines.results import main as results_main

    with pytest.raises(SystemExit) as stop:
        results_main([str(tmp_path / "nowhere"), "--seeds", "1"])
    error = capsys.readouterr().err
    assert stop.value.code == 2 and error.count("\n") == 1
    assert "not a run directory (no config.yaml)" in error and "nowhere" in error


def test_init_member_starts_from_one_network_of_an_ensemble(tmp_path: Path):
    student = Path(__file__).resolve().parents[1] / "baselines" / "models" / "paper_dagger"
    env = {**TINY["env"], "episode": {"action": "acceleration"}, "observation": {"kind": "local"}}
    env["observation"]["route_offset"] = False
    config = load_config("ppo", {**TINY, "env": env})
    scenario = build_scenario("paper", config)
    with pytest.raises(ValueError, match="averages 3 networks; start from one of them"):
        OnPolicyTrainer("ppo", scenario, config, 0, 1, tmp_path / "a", init=student)
    with pytest.raises(ValueError, match="has networks 0..2, got 3"):
        OnPolicyTrainer("ppo", scenario, config, 0, 1, tmp_path / "a", init=student, init_member=3)
    trainer = OnPolicyTrainer(
        "ppo", scenario, config, 0, 1, tmp_path / "b", init=student, init_member=1
    )
    layers, mean, std = load_policy_file(student).parts()[1]
    save_policy_file(tmp_path / "one", [layers], mean, std, observation="local", activation="tanh")
    obs = np.asarray(trainer.episodes.observe())
    np.testing.assert_allclose(
        TorchActorPolicy(trainer.model).act_batch(obs),
        load_policy_file(tmp_path / "one").act_batch(obs),
        atol=1e-5,
    )
    assert trainer.metadata()["init_member"] == 1
    # a member with statistics of its own starts from them, not from the file's
    first, _, _ = load_policy_file(student).parts()[0]
    wide = std > 1e-3  # RunningNorm floors a std at 1e-4: move only the slots that vary
    own = [(mean, std), (mean + 0.5 * std * wide, np.where(wide, 2.0 * std, std))]
    kind = {"observation": "local", "activation": "tanh"}
    save_policy_file(tmp_path / "own", [first, layers], mean, std, **kind, member_statistics=own)
    save_policy_file(tmp_path / "one_own", [layers], *own[1], **kind)
    again = OnPolicyTrainer(
        "ppo", scenario, config, 0, 1, tmp_path / "c", init=tmp_path / "own", init_member=1
    )
    np.testing.assert_allclose(
        TorchActorPolicy(again.model).act_batch(obs),
        load_policy_file(tmp_path / "one_own").act_batch(obs),
        atol=1e-5,
    )
