"""BenchMARL MAPPO / IPPO / MASAC training recipe (uav_formation_baselines.benchmarl_train)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("benchmarl")
import torch  # noqa: E402
from tensordict import TensorDict  # noqa: E402
from torchrl.envs.utils import ExplorationType, set_exploration_type  # noqa: E402

from uav_formation_baselines.benchmarl_train import (  # noqa: E402
    actor_module,
    formation_task,
    load_config,
    main,
    make_experiment,
)
from uav_formation_env.config_io import resolve_scenario, with_overrides  # noqa: E402
from uav_formation_env.policies import make_policy  # noqa: E402

TINY = {
    "frames": 400,
    "frames_per_batch": 200,
    "envs": 2,
    "minibatch": 100,
    "minibatch_iters": 1,
    "optimizer_steps": 2,
    "train_batch": 32,
    "hidden": [16, 16],
    "task": {"duration": 20.0},
}


def test_config_layers_and_unknown_keys(tmp_path: Path) -> None:
    config = load_config("masac", frames=1000, task={"reward": "paper"})
    assert config.frames == 1000 and config.optimizer_steps == 100
    assert config.task["reward"] == "paper"
    assert load_config("mappo").task["reward"] == "train"
    with pytest.raises(ValueError, match="unknown key 'framez'"):
        load_config("mappo", framez=3)
    with pytest.raises(ValueError, match="algo must be one of"):
        load_config("qmix")
    with pytest.raises(ValueError, match="must be a multiple of envs"):
        load_config("mappo", frames_per_batch=101, envs=10)


@pytest.mark.parametrize("algo", ["mappo", "masac"])
def test_exported_actor_is_the_deterministic_benchmarl_policy(algo: str, tmp_path: Path) -> None:
    config = load_config(algo, **TINY)
    task = formation_task("paper", config)
    experiment = make_experiment(algo, task, config, seed=0, folder=tmp_path)
    rng = np.random.default_rng(0)
    dim = 47 + 2  # the training preset's observation: the paper's layout and the route slots
    obs = torch.as_tensor(rng.normal(scale=0.5, size=(3, 5, dim)).astype(np.float32))
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        td = experiment.policy(TensorDict({("uav", "observation"): obs}, batch_size=[3]))
        exported = actor_module(experiment)(obs.reshape(15, dim))
    torch.testing.assert_close(exported[:, :3], td["uav", "action"].reshape(15, 3))
    torch.testing.assert_close(exported[:, 3:].exp(), td["uav", "scale"].reshape(15, 3))


def test_cli_trains_and_exports_a_policy_the_runner_flies(tmp_path: Path) -> None:
    sets = [f"{k}={v}" for k, v in TINY.items() if k != "task"] + ["task.duration=20.0"]
    assert main(["--algo", "ippo", "--out", str(tmp_path), "--set", *sets]) == 0
    rows = (tmp_path / "progress.csv").read_text().strip().splitlines()
    assert len(rows) == 3  # header + 2 iterations of 200 frames
    scenario = with_overrides(resolve_scenario("paper"), {"observation.route_offset": True})
    policy = make_policy(str(tmp_path), scenario)
    assert policy.act_batch(np.zeros((2, 5, 49), dtype=np.float32)).shape == (2, 5, 3)
    heldout = json.loads((tmp_path / "heldout.json").read_text())  # the end-of-training report
    assert heldout["seeds"] == [0, 1, 2] and heldout["reference"] == "lfpio"
    assert 0 < heldout["training_reward"] <= 1  # the last batch's reward "train", per step


def test_cli_reports_bad_settings_in_one_line(tmp_path: Path, capsys) -> None:
    assert main(["--algo", "mappo", "--out", str(tmp_path), "--set", "envs=0"]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "error: envs must be an integer >= 1, got 0"
    ]


def test_marl_eval_json_of_the_evaluations(tmp_path: Path) -> None:
    """``eval_episodes`` > 0: BenchMARL writes marl-eval's JSON (env -> task -> algorithm ->
    seed -> step -> metrics lists) of its first and last evaluation."""
    import json

    sets = [f"{k}={v}" for k, v in TINY.items() if k != "task"]
    sets += ["task.duration=20.0", "eval_episodes=2"]
    assert main(["--algo", "ippo", "--out", str(tmp_path), "--set", *sets]) == 0
    (path,) = (tmp_path / "benchmarl").glob("*/*.json")
    data = json.loads(path.read_text())
    (env,) = data.values()
    (task,) = env.values()
    (algorithm,) = task.values()
    assert list(algorithm) == ["seed_0"]
    steps = {k: v for k, v in algorithm["seed_0"].items() if k.startswith("step_")}
    assert len(steps) == 2  # the first and the last iteration
    for step in steps.values():
        assert len(step["return"]) == 2  # one per evaluation episode
        assert all(np.isfinite(step["return"]))
