"""Exported TorchScript policies (the RLlib recipe's policy.pt) run without their trainer."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from uav_formation_env.config_io import resolve_scenario, with_overrides
from uav_formation_env.evaluation import make_policy, run_episodes, summarise
from uav_formation_env.policies.learned import TorchScriptPolicy

torch = pytest.importorskip("torch")


def export(path: Path, in_dim: int = 47) -> Path:
    """A linear 'actor' whose mean is 10x the first three observation values (clipped later)."""
    layer = torch.nn.Linear(in_dim, 6, bias=False)
    with torch.no_grad():
        layer.weight.zero_()
        layer.weight[0, 0] = layer.weight[1, 1] = layer.weight[2, 2] = 10.0
        layer.weight[3:, :] = -1.0  # log-std: ignored by the deterministic action
    torch.jit.trace(layer, torch.zeros(1, in_dim)).save(str(path))
    return path


def test_the_action_is_the_clipped_mean(tmp_path: Path) -> None:
    policy = make_policy(str(export(tmp_path / "policy.pt")), resolve_scenario("paper"))
    assert isinstance(policy, TorchScriptPolicy)
    obs = np.zeros((2, 5, 47), dtype=np.float32)
    obs[0, 1, :3] = [0.05, -0.02, 0.5]
    actions = policy.act_batch(obs)
    assert actions.shape == (2, 5, 3)
    np.testing.assert_allclose(actions[0, 1], [0.5, -0.2, 1.0], rtol=1e-6)
    assert (actions[1] == 0).all()


def test_a_run_directory_names_its_policy_and_flies(tmp_path: Path) -> None:
    export(tmp_path / "policy.pt")
    scenario = with_overrides(resolve_scenario("paper"), {"duration": 4.0})
    batch = run_episodes(scenario, make_policy(str(tmp_path), scenario), [0])
    assert np.isfinite(summarise(batch)["realised_cost_mean"])


def test_wrong_size_and_missing_file_are_named(tmp_path: Path) -> None:
    path = export(tmp_path / "small.pt", in_dim=33)  # trained on 3 UAVs
    with pytest.raises(ValueError, match=r"observations of 47 values .* 5 UAVs"):
        make_policy(str(path), resolve_scenario("paper"))
    with pytest.raises(FileNotFoundError, match="not found"):
        make_policy(str(tmp_path / "none.pt"), resolve_scenario("paper"))
