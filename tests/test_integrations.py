"""Trainers use the environment unpatched: TorchRL's PettingZoo wrapper passes its own checker, and
every example of examples/ (TorchRL MAPPO, BenchMARL MAPPO, CleanRL-style PPO, SB3 PPO) runs its
``--quick`` path here: a few hundred env steps and one or two updates, finite returns, the
policy's parameters changed, a run directory that ``uav-formation evaluate --policy OUT`` flies
and the held-out mission report at the end. RLlib lives in its own venv: tests/rllib
(``bash tests/rllib/run.sh``).
"""

from __future__ import annotations

import importlib.util
import math
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from uav_formation_env import parallel_env
from uav_formation_env.config import TrainingRewardConfig

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
# the per-step reward with the devices is -log(1 + J / 100): J up to ~1e12 gives ~23 per UAV-step
MAX_STEP_REWARD = 30.0
HELDOUT = ["--heldout-seeds", "2", "--quiet"]  # the end-of-training report on two seeds


def load_example(name: str, *requires: str) -> ModuleType:
    """examples/<name>.py as a module (skipped if one of ``requires`` is not installed)."""
    for module in requires:
        pytest.importorskip(module, reason=f"{module} is not installed")
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def check_run_flies(result: dict, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """The example printed the held-out mission, and ``uav-formation evaluate --policy OUT
    --seeds 1 --quick`` flies the run directory it saved."""
    from uav_formation_env.cli import main as cli_main

    printed = capsys.readouterr().out
    assert "held-out mission" in printed and "LFPIO's" in printed
    assert result["heldout"] is not None and len(result["heldout"].seeds) == 2
    out = tmp_path / "evaluate"
    args = ["evaluate", "--policy", str(result["out"]), "--seeds", "1", "--quick", "--quiet"]
    assert cli_main([*args, "--out", str(out)]) == 0
    assert (out / "summary.json").is_file()


def check_returns(returns: list[float], steps_per_episode: int) -> None:
    """Some episodes ended, every return finite and within the training reward's bounds per UAV:
    at most 1 a step, at least minus the termination penalty."""
    assert len(returns) > 0, "no episode ended"
    values = np.asarray(returns, dtype=float)
    assert np.isfinite(values).all(), values
    assert (values <= steps_per_episode + 1e-9).all(), values
    assert (values >= -TrainingRewardConfig().termination_penalty).all(), values


# ---------------------------------------------------------------------------------- TorchRL
def test_torchrl_pettingzoo_wrapper_passes_check_env_specs() -> None:
    pettingzoo = pytest.importorskip("torchrl.envs.libs.pettingzoo")
    from torchrl.envs.utils import check_env_specs

    env = pettingzoo.PettingZooWrapper(env=parallel_env("paper"))
    check_env_specs(env)
    rollout = env.rollout(10)
    group = rollout["uav"]  # one group, named after the agents' prefix: the 5 UAVs
    assert group["observation"].shape == (10, 5, 47)
    info = rollout["next", "uav", "info"]
    assert info["neighbours"].shape == (10, 5, 5)
    reward = rollout["next", "uav", "reward"]
    np.testing.assert_allclose(reward[..., 0].numpy(), -info["J"].numpy(), rtol=1e-6)


def test_torchrl_sees_the_training_devices() -> None:
    pettingzoo = pytest.importorskip("torchrl.envs.libs.pettingzoo")
    env = pettingzoo.PettingZooWrapper(
        env=parallel_env("paper", episode__reward="log1p", episode__reward_scale=100.0)
    )
    rollout = env.rollout(5)
    reward = rollout["next", "uav", "reward"][..., 0].numpy()
    cost = rollout["next", "uav", "info", "J"].numpy()
    np.testing.assert_allclose(reward, -np.log1p(cost / 100.0), rtol=1e-5)
    assert np.abs(reward).max() < 20.0  # a few units, not the raw 1e2..1e8


def test_torchrl_mappo_example(tmp_path: Path, capsys) -> None:
    example = load_example("torchrl_mappo", "torchrl")
    # 2 x 200 frames, 100-step episodes
    result = example.main(["--quick", "--out", str(tmp_path / "run"), *HELDOUT])
    check_returns(result["returns"], 100)
    assert result["parameters_changed"]
    check_run_flies(result, tmp_path, capsys)


# ---------------------------------------------------------------------------------- BenchMARL
def test_benchmarl_task_class() -> None:
    pytest.importorskip("benchmarl")
    from uav_formation_baselines.benchmarl_task import (
        UavFormationTask,
        UavFormationTaskClass,
        uav_formation_task,
    )

    task = UavFormationTask.N3.get_task({"duration": 4.0})
    assert isinstance(task, UavFormationTaskClass)
    assert task.config["scenario"] == "n3" and task.config["reward"] == "train"
    assert task.supports_continuous_actions() and not task.supports_discrete_actions()
    env = task.get_env_fun(num_envs=1, continuous_actions=True, seed=0, device="cpu")()
    assert task.group_map(env) == {"uav": ["uav_0", "uav_1", "uav_2"]}
    assert task.max_steps(env) == 20
    # the training task's observation: the full layout and the two route slots
    assert task.observation_spec(env)["uav", "observation"].shape == (3, 33 + 2)
    assert task.action_spec(env)["uav", "action"].shape == (3, 3)
    assert task.state_spec(env)["state"].shape == (12 * 3 + 1 + 9,)
    assert {"J", "reward_route"} <= set(task.info_spec(env)["uav", "info"].keys())
    assert task.action_mask_spec(env) is None
    assert task.env_name() == "uav_formation"
    rollout = env.rollout(20)
    reward = rollout["next", "uav", "reward"]
    assert bool(rollout["next", "done"][-1]) and reward.abs().max() < MAX_STEP_REWARD

    assert UavFormationTask.PAPER.get_task().max_steps(env) == 1000
    # every registered scenario of one N has its task; the drawn fields and the local layout
    from uav_formation_env.config_io import SCENARIOS
    from uav_formation_env.scenes import n_uav_range

    fixed = {name for name in SCENARIOS if len(set(n_uav_range(SCENARIOS[name]()))) == 1}
    assert {member.name.lower() for member in UavFormationTask} == fixed
    for member, shape in (
        (UavFormationTask.RANDOM_FIELDS, (5, 49)),
        (UavFormationTask.SWARM_20, (20, 97)),
    ):
        env = member.get_task({"duration": 40.0}).get_env_fun(1, True, 0, "cpu")()
        assert env.rollout(3)["uav", "observation"].shape == (3, *shape)
    yaml_task = uav_formation_task("paper", reward="paper")
    assert yaml_task.name == "PAPER" and yaml_task.config["reward"] == "paper"
    with pytest.raises(ValueError, match="unknown uav_formation task option"):
        UavFormationTask.PAPER.get_task({"bogus": 1})
    with pytest.raises(ValueError, match="reward must be one of"):
        UavFormationTask.PAPER.get_task({"reward": "weird"})


@pytest.mark.parametrize("backend", ["pettingzoo", "torch"])
def test_benchmarl_mappo_example(backend: str, tmp_path: Path, capsys) -> None:
    example = load_example("benchmarl_mappo", "benchmarl")
    # 1 iteration of 200 frames, 100-step episodes
    result = example.main(["--quick", "--backend", backend, "--out", str(tmp_path), *HELDOUT])
    assert result["iterations"] == 1
    assert result["finite"] and -10.0 <= result["mean_return"] <= 100  # reward "train"
    assert result["parameters_changed"]
    check_run_flies(result, tmp_path, capsys)


def test_benchmarl_torch_backend_task() -> None:
    """The torch backend's env is vectorised (BenchMARL uses it as it is) with the same specs."""
    pytest.importorskip("benchmarl")
    from uav_formation_baselines.benchmarl_task import UavFormationTask

    # every copy from t = 0 (the training preset staggers them), so all end at step 20
    config = {"duration": 4.0, "backend": "torch", "overrides": {"episode.start": "zero"}}
    task = UavFormationTask.N3.get_task(config)
    env = task.get_env_fun(num_envs=4, continuous_actions=True, seed=0, device="cpu")()
    assert env.batch_size == (4,)
    assert task.group_map(env) == {"uav": ["uav_0", "uav_1", "uav_2"]}
    # BenchMARL builds its models from the unbatched specs
    assert task.observation_spec(env)["uav", "observation"].shape == (3, 33 + 2)
    assert task.action_spec(env)["uav", "action"].shape == (3, 3)
    assert task.state_spec(env)["state"].shape == (12 * 3 + 1 + 9,)
    assert "J" in task.info_spec(env)["uav", "info"]
    rollout = env.rollout(20)
    assert bool(rollout["next", "done"][:, -1].all())
    assert rollout["next", "uav", "reward"].abs().max() < MAX_STEP_REWARD
    with pytest.raises(ValueError, match="backend must be one of"):
        UavFormationTask.N3.get_task({"backend": "jax"})


# ---------------------------------------------------------------------------------- CleanRL
def test_cleanrl_ppo_example(tmp_path: Path, capsys) -> None:
    example = load_example("cleanrl_ppo", "torch")
    # 8 copies x 32 steps = 256 steps x 5 agents, 20-step episodes, one update
    result = example.main(["--quick", "--duration", "4", "--out", str(tmp_path), *HELDOUT])
    assert result["rewards"].shape == (32, 8, 5)
    assert np.isfinite(result["rewards"]).all()
    check_returns(result["returns"], 20)
    assert result["parameters_changed"]
    check_run_flies(result, tmp_path, capsys)


# ---------------------------------------------------------------------------------- SB3
def test_sb3_ppo_example(tmp_path: Path, capsys) -> None:
    example = load_example("sb3_ppo", "stable_baselines3", "torch")
    # 1280 agent-steps, 100-step episodes
    result = example.main(["--quick", "--out", str(tmp_path), *HELDOUT])
    check_returns(result["returns"], 100)
    assert result["parameters_changed"]
    check_run_flies(result, tmp_path, capsys)


# ---------------------------------------------------------------------------------- RLlib
def test_rllib_is_tested_in_its_own_venv() -> None:
    """tests/rllib needs ray (its own venv, gymnasium 1.2.2): the main run does not collect it,
    its runner script is valid bash, and the recipe parses its arguments without RLlib."""
    run = ROOT / "tests" / "rllib" / "run.sh"
    assert subprocess.run(["bash", "-n", str(run)], check=False).returncode == 0
    if importlib.util.find_spec("ray") is None:
        collected = subprocess.run(
            [sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider",
             str(ROOT / "tests" / "rllib")],
            capture_output=True, text=True, check=False, cwd=ROOT,
        )  # fmt: skip
        assert "test_rllib" not in collected.stdout, collected.stdout
    from uav_formation_baselines import rllib_ppo  # the recipe: imports ray only when it runs

    load_example("rllib_ppo")  # the example is a thin call of the recipe
    args = rllib_ppo.parse_args(["--quick"])
    assert (args.iterations, args.batch) == (1, 400) and math.isclose(args.duration, 40.0)
