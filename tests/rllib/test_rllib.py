"""RLlib smoke tests (new API stack), run in their own virtual environment by tests/rllib/run.sh.

``ray[rllib]`` pins a gymnasium older than the main environment's, so this folder is not collected
by the main ``python -m pytest`` run. One PPO iteration of the recipe
(:mod:`uav_formation_baselines.rllib_ppo`) on the paper's scenario under the training preset:
finite returns of a sane size, the shared module's parameters changed, a checkpoint that resumes
and an exported policy that ``uav-formation evaluate`` runs.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("ray.rllib", reason="ray[rllib] is not installed (run tests/rllib/run.sh)")

from uav_formation_baselines import rllib_ppo  # noqa: E402
from uav_formation_env.cli import main as cli  # noqa: E402


def test_parallel_pettingzoo_env_wraps_the_env_unpatched() -> None:
    env = rllib_ppo.make_env({"scenario": "paper", "reward": "train"})
    obs, infos = env.reset(seed=0)
    assert sorted(obs) == [f"uav_{i}" for i in range(5)]
    assert obs["uav_0"].shape == (47 + 2,)  # the paper's layout and the training task's route slots
    actions = {agent: env.action_space[agent].sample() for agent in obs}
    obs, rewards, terminateds, truncateds, infos = env.step(actions)
    assert "__all__" in terminateds and "__all__" in truncateds
    assert all(np.isfinite(r) and -10.0 <= r <= 1.0 for r in rewards.values())  # reward "train"


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    """One quick PPO iteration through the command line, on a local Ray instance."""
    out = tmp_path_factory.mktemp("rllib")
    assert (
        cli(["train", "--algo", "rllib-ppo", "--quick", "--num-cpus", "2", "--out", str(out)]) == 0
    )
    return out


def test_one_ppo_iteration_with_a_shared_module(run: Path) -> None:
    import yaml

    config = yaml.safe_load((run / "config.yaml").read_text())
    returns = config["returns"]
    assert len(returns) == 1
    assert all(math.isfinite(r) for r in returns), returns
    assert all(abs(r) < 1e6 for r in returns), returns  # raw returns are -2e11..-4e12
    assert config["parameters_changed"]
    assert (run / "checkpoint").is_dir() and (run / "progress.csv").is_file()
    heldout = json.loads((run / "heldout.json").read_text())  # the end-of-training report
    assert heldout["reference"] == "lfpio" and len(heldout["seeds"]) == 3


def test_evaluate_from_the_exported_policy(run: Path, tmp_path: Path) -> None:
    out = tmp_path / "eval"
    args = [
        "evaluate",
        "--policy",
        str(run),
        "--scenario",
        str(run / "scenario.yaml"),
    ]
    assert cli([*args, "--seeds", "2", "--quiet", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["mission"]["episodes"] == 2
    assert math.isfinite(summary["realised_cost_mean"])
    # the run directory names the policy too
    assert cli(["evaluate", "--policy", str(run), "--scenario", str(run / "scenario.yaml"),
                "--seeds", "1", "--quiet", "--out", str(tmp_path / "dir")]) == 0  # fmt: skip


def test_training_resumes_from_the_checkpoint(run: Path) -> None:
    before = (run / "policy.npz").read_bytes()
    assert cli(["train", "--algo", "rllib-ppo", "--quick", "--num-cpus", "2", "--resume",
                "--out", str(run)]) == 0  # fmt: skip
    assert (run / "policy.npz").read_bytes() != before
