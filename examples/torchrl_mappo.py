"""TorchRL MAPPO on the paper's scenario, in the style of TorchRL's multi-agent PPO tutorial.

TorchRL's ``PettingZooWrapper`` takes ``parallel_env("paper", reward="train")`` unpatched and
groups the five UAVs as ``"uav"`` (observations ``("uav", "observation")`` of shape (5, 47),
actions ``("uav", "action")`` (5, 3) in [-1, 1]). The actor is one MLP shared by the agents
(decentralised: each UAV's own observation), the critic one shared MLP over all agents'
observations (centralised: MAPPO); ``ClipPPOLoss`` with GAE, a ``Collector`` (TorchRL 0.11's
name of ``SyncDataCollector``, which is deprecated there).

    pip install torch==2.13.0 && pip install -e ".[torchrl]"
    python examples/torchrl_mappo.py --iterations 50 --out runs/torchrl_mappo
    python examples/torchrl_mappo.py --quick --out /tmp/torchrl   # 2 iterations of 200 frames
    uav-formation evaluate --policy runs/torchrl_mappo --seeds 10

The run directory holds ``policy.json`` + ``policy.npz`` (the shared actor: observation -> tanh
of the TanhNormal's location, the deterministic action; :mod:`uav_formation_baselines.torch_policy`)
and ``scenario.yaml``; the run ends with the mission on held-out seeds beside LFPIO's
(:func:`uav_formation_env.evaluation.heldout.report_run`).

The training task (``reward="train"``, docs/training.md) keeps the reward in (0, 1] per UAV
and step; the paper's raw -J_i returns are -2e11..-4e12 per episode.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import torch
from tensordict.nn import NormalParamExtractor, TensorDictModule
from torch import nn
from torchrl.collectors import Collector  # SyncDataCollector's name since TorchRL 0.11
from torchrl.data.replay_buffers import ReplayBuffer
from torchrl.data.replay_buffers.samplers import SamplerWithoutReplacement
from torchrl.data.replay_buffers.storages import LazyTensorStorage
from torchrl.envs import RewardSum, TransformedEnv
from torchrl.envs.libs.pettingzoo import PettingZooWrapper
from torchrl.envs.utils import check_env_specs
from torchrl.modules import MultiAgentMLP, ProbabilisticActor, TanhNormal
from torchrl.objectives import ClipPPOLoss, ValueEstimators

from uav_formation_baselines.torch_policy import save_policy
from uav_formation_env import parallel_env
from uav_formation_env.config import Scenario
from uav_formation_env.config_io import resolve_scenario, save_scenario, with_overrides
from uav_formation_env.evaluation.heldout import report_run
from uav_formation_env.tasks import training_scenario

GROUP = "uav"  # the group TorchRL infers from the agent names uav_0..uav_4


def evaluated_scenario(scenario: str = "paper", duration: float | None = None) -> Scenario:
    """The task: ``scenario`` with ``duration`` (the training preset goes on top)."""
    resolved = resolve_scenario(scenario)
    return resolved if duration is None else with_overrides(resolved, {"duration": duration})


def make_env(scenario: str = "paper", duration: float | None = None, seed: int = 0):
    """The wrapped env with an episode-return counter, ``("uav", "episode_reward")``."""
    env = parallel_env(evaluated_scenario(scenario, duration), reward="train")
    base = PettingZooWrapper(env=env, seed=seed)
    return TransformedEnv(
        base, RewardSum(in_keys=[base.reward_key], out_keys=[(GROUP, "episode_reward")])
    )


def make_modules(env, hidden: int) -> tuple[ProbabilisticActor, TensorDictModule]:
    """The shared actor (TanhNormal over [-1, 1]^3) and the centralised shared critic."""
    n_agents = env.full_action_spec[env.action_key].shape[-2]
    obs_dim = env.observation_spec[GROUP, "observation"].shape[-1]
    act_dim = env.full_action_spec[env.action_key].shape[-1]
    actor_net = nn.Sequential(
        MultiAgentMLP(
            n_agent_inputs=obs_dim,
            n_agent_outputs=2 * act_dim,  # loc and scale
            n_agents=n_agents,
            centralized=False,
            share_params=True,
            depth=2,
            num_cells=hidden,
            activation_class=nn.Tanh,
        ),
        NormalParamExtractor(),
    )
    actor_module = TensorDictModule(
        actor_net, in_keys=[(GROUP, "observation")], out_keys=[(GROUP, "loc"), (GROUP, "scale")]
    )
    action_spec = env.full_action_spec_unbatched[env.action_key]
    actor = ProbabilisticActor(
        module=actor_module,
        spec=action_spec,
        in_keys=[(GROUP, "loc"), (GROUP, "scale")],
        out_keys=[env.action_key],
        distribution_class=TanhNormal,
        distribution_kwargs={"low": action_spec.space.low, "high": action_spec.space.high},
        return_log_prob=True,
    )
    critic_net = MultiAgentMLP(
        n_agent_inputs=obs_dim,
        n_agent_outputs=1,
        n_agents=n_agents,
        centralized=True,  # MAPPO: every agent's value sees all observations
        share_params=True,
        depth=2,
        num_cells=hidden,
        activation_class=nn.Tanh,
    )
    critic = TensorDictModule(
        critic_net, in_keys=[(GROUP, "observation")], out_keys=[(GROUP, "state_value")]
    )
    return actor, critic


class ExportedActor(nn.Module):
    """The shared actor as the exported policy contract: (M, dim) -> (M, 6), the TanhNormal's
    loc (the deterministic action is tanh(loc), the policy file's ``"tanh"``) and log(scale).
    ``MultiAgentMLP`` keeps the shared parameters apart from its layers; they are copied into a
    plain ``nn.Sequential``."""

    def __init__(self, actor_net: nn.Sequential) -> None:
        super().__init__()
        multi, self.extract = actor_net[0], actor_net[1]
        layers = []
        for k, layer in enumerate(multi._empty_net):
            if isinstance(layer, nn.Linear):
                copy = nn.Linear(layer.in_features, layer.out_features)
                copy.weight.data.copy_(multi.params[str(k), "weight"].data)
                copy.bias.data.copy_(multi.params[str(k), "bias"].data)
                layers.append(copy)
            else:
                layers.append(type(layer)())
        self.net = nn.Sequential(*layers)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        loc, scale = self.extract(self.net(obs))
        return torch.cat([loc, scale.log()], dim=-1)


def save_run(actor_net: nn.Sequential, scenario: Scenario, out: Path, sample) -> None:
    """The run directory ``uav-formation evaluate --policy OUT`` flies: the policy, scenario."""
    kind = scenario.observation.kind  # the exported actor's first 3 outputs are loc: tanh(loc)
    save_policy(ExportedActor(actor_net), out, sample, observation=kind, action="tanh")
    save_scenario(scenario, out / "scenario.yaml")


def main(argv: list[str] | None = None) -> dict[str, Any]:
    args = parse_args(argv)
    torch.manual_seed(args.seed)
    env = make_env(args.scenario, args.duration, args.seed)
    check_env_specs(env)
    rollout = env.rollout(5)
    print(f"rollout: {tuple(rollout[GROUP, 'observation'].shape)} observations")

    actor, critic = make_modules(env, args.hidden)
    collector = Collector(
        env,
        actor,
        frames_per_batch=args.frames_per_batch,
        total_frames=args.frames_per_batch * args.iterations,
    )
    buffer = ReplayBuffer(
        storage=LazyTensorStorage(args.frames_per_batch),
        sampler=SamplerWithoutReplacement(),
        batch_size=args.minibatch,
    )
    loss_module = ClipPPOLoss(
        actor_network=actor,
        critic_network=critic,
        clip_epsilon=0.2,
        entropy_coeff=1e-3,
        normalize_advantage=False,
    )
    loss_module.set_keys(
        reward=env.reward_key,
        action=env.action_key,
        value=(GROUP, "state_value"),
        done=(GROUP, "done"),
        terminated=(GROUP, "terminated"),
    )
    loss_module.make_value_estimator(ValueEstimators.GAE, gamma=0.99, lmbda=0.95)
    gae = loss_module.value_estimator
    optimizer = torch.optim.Adam(loss_module.parameters(), args.lr)
    before = [p.detach().clone() for p in actor.parameters()]

    returns: list[float] = []
    start = time.perf_counter()
    for iteration, data in enumerate(collector):
        with torch.no_grad():
            gae(
                data,
                params=loss_module.critic_network_params,
                target_params=loss_module.target_critic_network_params,
            )
        buffer.extend(data.reshape(-1))
        for _ in range(args.epochs):
            for _ in range(args.frames_per_batch // args.minibatch):
                losses = loss_module(buffer.sample())
                loss = losses["loss_objective"] + losses["loss_critic"] + losses["loss_entropy"]
                loss.backward()
                torch.nn.utils.clip_grad_norm_(loss_module.parameters(), 1.0)
                optimizer.step()
                optimizer.zero_grad()
        collector.update_policy_weights_()
        done = data["next", GROUP, "done"]
        ended = data["next", GROUP, "episode_reward"][done]  # per agent, of episodes that ended
        mean = ended.mean().item() if ended.numel() else float("nan")
        returns.extend(ended.tolist())
        print(
            f"iteration {iteration + 1}: {data.numel()} frames, {int(done.any(-2).sum())} "
            f"episode(s) ended, mean episode return per UAV {mean:.4g}"
        )
    collector.shutdown()
    changed = any(not torch.equal(b, p) for b, p in zip(before, actor.parameters()))
    seconds = time.perf_counter() - start
    print(f"{args.iterations} iteration(s) in {seconds:.1f} s; actor parameters changed: {changed}")
    out = Path(args.out)
    sample = data[GROUP, "observation"].reshape(-1, data[GROUP, "observation"].shape[-1])[:64]
    trained = training_scenario(evaluated_scenario(args.scenario, args.duration))
    save_run(actor.module[0].module, trained, out, sample)
    recent = float(sum(returns[-100:]) / len(returns[-100:])) if returns else None
    report = report_run(out, args.heldout_seeds, training_reward=recent, progress=not args.quiet)
    return {
        "returns": returns,
        "parameters_changed": changed,
        "seconds": seconds,
        "out": out,
        "heldout": report,
    }


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n")[0] + " Measured on a 2-core machine shared with other "
        "jobs: one default iteration (6000 frames, one line each) took 500 s, so the 20 default "
        "iterations take hours; --quick ~40 s in all.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("--scenario", default="paper", help="registered name or YAML path")
    parser.add_argument("--iterations", type=int, default=20)
    parser.add_argument("--frames-per-batch", type=int, default=6000, help="env steps")
    parser.add_argument("--minibatch", type=int, default=400)
    parser.add_argument("--epochs", type=int, default=10)
    parser.add_argument("--lr", type=float, default=3e-4)
    parser.add_argument("--hidden", type=int, default=256)
    parser.add_argument("--duration", type=float, default=None, help="episode length [s]")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="runs/torchrl_mappo", help="run directory")
    parser.add_argument(
        "--heldout-seeds", type=int, default=3, help="held-out seeds flown at the end (0: none)"
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="2 iterations of 200 frames, 20 s episodes: the smoke test",
    )
    args = parser.parse_args(argv)
    if args.quick:
        args.iterations, args.frames_per_batch, args.minibatch, args.epochs = 2, 200, 100, 2
        args.hidden = 32
        if args.duration is None:
            args.duration = 20.0
    return args


if __name__ == "__main__":
    main()
