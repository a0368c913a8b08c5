"""The batched TorchRL EnvBase on the torch backend (envs/torchrl_env.py, issue 14).

TorchRL's own checker validates the specs against real rollouts; the env's numbers must be the
numpy episode layer's (same seeds, same actions), and partial resets must reset only the copies
TorchRL names.
"""

from __future__ import annotations

import numpy as np
import pytest

from uav_formation_env import envs
from uav_formation_env.episode import FormationEpisodes
from uav_formation_env.scenarios import random_fields_scenario

torch = pytest.importorskip("torch")
pytest.importorskip("torchrl")

from tensordict import TensorDict  # noqa: E402
from torchrl.envs.utils import check_env_specs  # noqa: E402

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


@pytest.mark.parametrize("device", DEVICES)
def test_check_env_specs(device):
    env = envs.torchrl_env("paper", num_envs=3, device=device, seed=0, duration=4.0)
    check_env_specs(env)
    assert env.group_map == {"uav": [f"uav_{i}" for i in range(5)]}
    assert env.full_action_spec["uav", "action"].shape == (3, 5, 3)
    assert env.observation_spec["uav", "observation"].shape == (3, 5, 47)
    assert env.observation_spec["state"].shape == (3, 12 * 5 + 1 + 25)


def test_local_layout_and_drawn_scenes():
    env = envs.torchrl_env(random_fields_scenario(), num_envs=2, seed=1)
    check_env_specs(env)


def test_rollout_equals_the_numpy_episode_layer():
    """Same seed, same actions: the observations, rewards, costs and flags of numpy."""
    batch, steps = 2, 40
    env = envs.torchrl_env("paper", num_envs=batch, seed=7, duration=6.0)
    reference = FormationEpisodes(env.scenario, batch)
    expected = reference.reset(seed=7)
    td = env.reset()
    np.testing.assert_allclose(td["uav", "observation"].numpy(), expected.observation, rtol=1e-6)
    rng = np.random.default_rng(0)
    for _ in range(steps):
        actions = rng.uniform(-1, 1, (batch, 5, 3)).astype(np.float32)
        expected = reference.step(actions)
        td["uav", "action"] = torch.as_tensor(actions)
        out = env.step(td)["next"]
        np.testing.assert_allclose(
            out["uav", "observation"].numpy(), expected.observation, rtol=1e-6, atol=1e-6
        )
        np.testing.assert_allclose(
            out["uav", "reward"].numpy()[..., 0], expected.reward, rtol=1e-6, atol=1e-6
        )
        np.testing.assert_allclose(
            out["uav", "info", "J"].numpy()[..., 0], expected.cost, rtol=1e-6, atol=1e-6
        )
        np.testing.assert_array_equal(out["truncated"].numpy()[:, 0], expected.truncated)
        td = out.exclude("uav").clone()
        td["uav"] = out["uav"].exclude("reward").clone()
    assert bool(out["done"].all())  # 6 s = 30 steps: every copy reached its duration


def test_partial_reset_resets_only_the_named_copies():
    env = envs.torchrl_env("paper", num_envs=3, seed=0, duration=10.0)
    td = env.reset()
    td["uav", "action"] = torch.zeros(3, 5, 3)
    for _ in range(5):
        td = env.step(td)["next"].clone()
        td["uav", "action"] = torch.zeros(3, 5, 3)
    before = env.episodes.sim.t.clone()
    mask = torch.tensor([[False], [True], [False]])
    env.reset(TensorDict({"_reset": mask}, batch_size=[3]))
    after = env.episodes.sim.t
    assert float(after[1]) == 0.0
    assert torch.equal(after[[0, 2]], before[[0, 2]])


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="num_envs must be an integer >= 1"):
        envs.torchrl_env("paper", num_envs=0)
    with pytest.raises(ValueError, match="device must name a torch device"):
        envs.torchrl_env("paper", device="moon")
    from uav_formation_env.config_io import paper_scenario
    from uav_formation_env.envs.torchrl_adapter import FormationTorchRLEnv
    from uav_formation_env.sim_options import SimOptions

    with pytest.raises(ValueError, match="options.backend must be 'torch', got 'numpy'"):
        FormationTorchRLEnv(paper_scenario(), 1, SimOptions())


def test_compiled_env_passes_the_spec_check() -> None:
    """torchrl_env(compile=True): the whole step through torch.compile (3 copies: the shapes
    test_backend_sim compiles for) and the same specs."""
    env = envs.torchrl_env(num_envs=3, compile=True, seed=0)
    assert env.episodes.sim.options.compile
    check_env_specs(env)
    assert env.episodes.sim._compiled and env.episodes._compiled  # both compiled, in use
