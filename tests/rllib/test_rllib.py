"""RLlib smoke test (new API stack), run in its own virtual environment by tests/rllib/run.sh.

``ray[rllib]`` pins a gymnasium older than the main environment's, so this folder is not collected
by the main ``python -m pytest`` run. One PPO iteration of examples/rllib_ppo.py on the paper's
scenario with the training devices: finite episode returns of a sane size, and the shared
module's parameters changed.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("ray.rllib", reason="ray[rllib] is not installed (run tests/rllib/run.sh)")

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "rllib_ppo.py"


def load_example():
    spec = importlib.util.spec_from_file_location("rllib_ppo_example", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_parallel_pettingzoo_env_wraps_the_env_unpatched() -> None:
    example = load_example()
    env = example.make_env({"scenario": "paper", **example.TRAINING_DEVICES})
    obs, infos = env.reset(seed=0)
    assert sorted(obs) == [f"uav_{i}" for i in range(5)]
    assert obs["uav_0"].shape == (47,)
    actions = {agent: env.action_space[agent].sample() for agent in obs}
    obs, rewards, terminateds, truncateds, infos = env.step(actions)
    assert "__all__" in terminateds and "__all__" in truncateds
    assert all(np.isfinite(r) and abs(r) < 50.0 for r in rewards.values())  # log1p: a few units


def test_one_ppo_iteration_with_a_shared_module() -> None:
    example = load_example()
    result = example.main(["--quick", "--num-cpus", "1"])
    returns = result["returns"]
    assert len(returns) == 1
    assert all(math.isfinite(r) for r in returns), returns
    assert all(abs(r) < 1e6 for r in returns), returns  # raw returns are -2e11..-4e12
    assert result["parameters_changed"]
