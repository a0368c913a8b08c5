"""Ensembles of learned policies (uav_formation_baselines.ensemble)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

torch = pytest.importorskip("torch")

from uav_formation_baselines.ensemble import build_ensemble, main, rank_runs  # noqa: E402
from uav_formation_baselines.torch_policy import NormalisedMLP, save_policy  # noqa: E402
from uav_formation_env.config_io import resolve_scenario, save_scenario, with_overrides  # noqa: E402
from uav_formation_env.episode import FormationEpisodes  # noqa: E402
from uav_formation_env.policies import make_policy  # noqa: E402
from uav_formation_env.policies.policy_file import load_policy_file  # noqa: E402
from uav_formation_env.scenes import seeds_by_n_uav  # noqa: E402

LOCAL = with_overrides(resolve_scenario("paper"), {"observation": {"kind": "local"}})
DIM = 95  # the local layout's observation length at N = 5


def fake_run(
    path: Path,
    seed: int,
    completed: int,
    cost: float,
    episodes: int = 40,
    scenario=LOCAL,
    dim: int = DIM,
) -> Path:
    """A finished run of a seeded random MLP: its chosen round 1 scored (completed, cost) by
    ``--select``; round 0 scored better, so a reader of the wrong row is caught."""
    torch.manual_seed(seed)
    model = NormalisedMLP(np.zeros(dim), np.ones(dim), (8,), "tanh")
    sample = np.random.default_rng(seed).normal(size=(4, dim)).astype(np.float32)
    save_policy(model, path, sample, observation=scenario.observation.kind)
    save_scenario(scenario, path / "scenario.yaml")
    record = {"algorithm": "dagger", "seed": seed, "best_round": 1, "agent_steps": 100 * seed}
    record["wall_time_s"] = 10.0 * seed
    (path / "config.yaml").write_text(yaml.safe_dump(record))
    (path / "selection.csv").write_text(
        "round,validation_completed,validation_episodes,validation_cost\n"
        f"0,{episodes},{episodes},1.0\n1,{completed},{episodes},{cost}\n"
    )
    return path


def test_the_top_runs_by_validation_are_averaged_into_one_loadable_policy(tmp_path: Path) -> None:
    runs = [
        fake_run(tmp_path / "a", 1, completed=38, cost=7.0e5),
        fake_run(tmp_path / "b", 2, completed=40, cost=7.5e5),  # most missions: first
        fake_run(tmp_path / "c", 3, completed=38, cost=6.9e5),  # same count, cheaper than a
    ]
    assert [run.name for run, _ in rank_runs(runs)] == ["b", "c", "a"]
    record = build_ensemble(runs, tmp_path / "ens", top=2)
    assert [Path(m["run"]).name for m in record["members"]] == ["b", "c"]
    assert record["members"][0]["validation_completed"] == 40
    assert (record["agent_steps"], record["wall_time_s"]) == (500, 50.0)  # b and c summed
    assert record["algorithm"] == "dagger_ensemble"
    assert yaml.safe_load((tmp_path / "ens" / "config.yaml").read_text()) == record
    obs = np.random.default_rng(0).normal(size=(7, DIM))
    members = [load_policy_file(tmp_path / name) for name in ("b", "c")]
    loaded = load_policy_file(tmp_path / "ens")
    want = (members[0].outputs(obs) + members[1].outputs(obs)) / 2
    np.testing.assert_allclose(loaded.outputs(obs), want, atol=1e-5)
    policy = make_policy(str(tmp_path / "ens"), LOCAL)  # what evaluate --policy DIR loads
    assert policy.act_batch(np.zeros((1, 5, DIM), np.float32)).shape == (1, 5, 3)


def test_members_of_other_scenes_or_scores_are_refused_in_one_line(tmp_path: Path, capsys) -> None:
    full = resolve_scenario("paper")
    runs = [
        fake_run(tmp_path / "a", 1, 40, 7e5),
        fake_run(tmp_path / "b", 2, 39, 7e5, scenario=full),
    ]
    with pytest.raises(ValueError, match="b/scenario.yaml differs from"):
        build_ensemble(runs, tmp_path / "ens")
    assert not (tmp_path / "ens").exists()
    fake_run(tmp_path / "c", 3, 8, 7e5, episodes=8)
    with pytest.raises(ValueError, match="different numbers of seeds: \\[8, 40\\]"):
        rank_runs([tmp_path / "a", tmp_path / "c"])
    assert main(["--out", str(tmp_path / "ens"), str(tmp_path / "a"), "--top", "0"]) == 2
    assert capsys.readouterr().err.strip() == "error: top must be an integer >= 1, got 0"
    assert main(["--out", str(tmp_path / "ens"), str(tmp_path / "none")]) == 2
    assert "is not a finished run: no policy.json" in capsys.readouterr().err
    lost = fake_run(tmp_path / "d", 4, 40, 7e5)
    (lost / "selection.csv").write_text(
        "round,validation_completed,validation_episodes,validation_cost\n0,40,40,1.0\n"
    )
    with pytest.raises(ValueError, match="selection.csv has no row for the chosen round 1"):
        rank_runs([lost])


def test_an_ensemble_of_a_scene_distribution_over_n_is_built_and_flies_any_n(
    tmp_path: Path,
) -> None:
    swarm = resolve_scenario("random_swarm")  # N drawn in 3..10: one observation length for all
    groups = seeds_by_n_uav(swarm, list(range(6)))
    assert len(groups) > 1  # seeds 0-5 draw several N
    n_uav, seeds = next(iter(groups.items()))
    dim = FormationEpisodes(swarm, 1, n_uav=n_uav).reset(seed=seeds[:1]).observation.shape[-1]
    runs = [fake_run(tmp_path / name, k, 30, 7e5, scenario=swarm, dim=dim) for k, name in
            enumerate("ab", start=1)]  # fmt: skip
    build_ensemble(runs, tmp_path / "ens")
    policy = make_policy(str(tmp_path / "ens"), swarm)
    for n_uav, group in groups.items():
        obs = FormationEpisodes(swarm, len(group), n_uav=n_uav).reset(seed=group).observation
        assert policy.act_batch(obs).shape == (len(group), n_uav, 3)


def test_on_policy_runs_ensemble_by_their_last_evaluation_in_their_action_mode(
    tmp_path: Path, capsys
) -> None:
    from uav_formation_baselines.onpolicy_config import load_config
    from uav_formation_baselines.onpolicy_trainer import OnPolicyTrainer, build_scenario
    from uav_formation_env.policies.action_modes import VelocitySetpointPolicy

    tiny = {"copies": 2, "rollout_steps": 4, "epochs": 1, "minibatches": 1, "eval_seeds": 1}
    config = load_config("ppo", {**tiny, "hidden": [8], "env": {"duration": 2.0}})
    scenario = build_scenario("paper", config)
    frames = config.rollout_steps * config.copies * scenario.n_uav
    runs = []
    for seed in (0, 1):
        run = tmp_path / f"ppo_s{seed}"
        OnPolicyTrainer("ppo", scenario, config, seed, frames, run).train(progress=False)
        runs.append(run)
    # the last evaluation scores a run; the better one ranks first
    lines = (runs[1] / "progress.csv").read_text().splitlines()
    header, last = lines[0].split(","), lines[-1].split(",")
    last[header.index("eval_completed")] = "1"
    last[header.index("eval_J")] = "5.0"
    (runs[1] / "progress.csv").write_text("\n".join([*lines[:-1], ",".join(last)]) + "\n")
    ranked = rank_runs(runs)
    assert ranked[0][0] == runs[1] and ranked[0][1]["validation_cost"] == 5.0
    assert ranked[0][1]["source"] == "progress.csv" and ranked[0][1]["round"] == 1
    record = build_ensemble(runs, tmp_path / "ens")
    assert record["algorithm"] == "ppo_ensemble" and record["agent_steps"] == 2 * frames
    ensemble = load_policy_file(tmp_path / "ens")
    assert ensemble.header["algorithm"] == "ppo_ensemble" and ensemble.header["members"] == 2
    # each member clips its own normalised observation: far out of its statistics, too
    far = np.random.default_rng(0).normal(scale=1e3, size=(16, ensemble.observation_size))
    members = [load_policy_file(run) for run in runs]
    want = sum(member.outputs(far) for member in members) / 2
    np.testing.assert_allclose(ensemble.outputs(far), want, atol=1e-5)
    # a run's best policy (the trainer kept one) is a member like a run, named with its run
    best = runs[0] / "best"
    assert rank_runs([best])[0][1]["source"] == "selected_by"
    out = ["--out", str(tmp_path / "ens2"), str(best), str(runs[1]), "--heldout-seeds", "0"]
    assert main(out) == 0
    assert "(ppo_s1, ppo_s0/best)" in capsys.readouterr().out  # ranked: s1 scored better
    # trained in the velocity action mode: flown through the set-point loop, as its members
    flown = make_policy(str(tmp_path / "ens"), scenario)
    assert isinstance(flown, VelocitySetpointPolicy)
