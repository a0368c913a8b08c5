"""CleanRL-style PPO in plain torch, one policy shared by all UAVs, on the batched episode layer.

No gym wrapper: :class:`uav_formation_env.episode.FormationEpisodes` steps B copies of the
scenario at once (observations (B, N, 47), actions (B, N, 3), rewards (B, N), ``step.done`` (B,))
and resets a copy as soon as its episode ends (``autoreset=True``). Parameter sharing: the policy
sees the B x N agents as one batch of B N independent observations; the value is per agent
(IPPO with shared parameters). A truncated episode (duration, divergence) is bootstrapped from
the value of its ``final_observation``; a terminated one (out of the corridor) is not.

    python examples/cleanrl_ppo.py --updates 100 --out runs/cleanrl_ppo
    python examples/cleanrl_ppo.py --quick --out /tmp/cleanrl  # 1 update of 8 copies x 32 steps
    uav-formation evaluate --policy runs/cleanrl_ppo --seeds 10

The run directory holds ``policy.json`` + ``policy.npz`` (the actor's mean, in the project's
policy file format: :mod:`uav_formation_baselines.torch_policy`) and ``scenario.yaml``; the
run ends with the mission on held-out seeds beside LFPIO's
(:func:`uav_formation_env.evaluation.heldout.report_run`).

The training task (``reward="train"``, docs/training.md) keeps the reward in (0, 1] per UAV
and step (the paper's raw -J_i returns are -2e11..-4e12 per episode); its first reset spreads the
copies over the mission, so that a rollout of T steps holds every phase of it.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.distributions import Normal

from uav_formation_baselines.torch_policy import save_policy
from uav_formation_env.config import Scenario
from uav_formation_env.config_io import resolve_scenario, save_scenario, with_overrides
from uav_formation_env.episode import FormationEpisodes
from uav_formation_env.evaluation.heldout import report_run
from uav_formation_env.tasks import training_scenario


def layer_init(layer: nn.Linear, std: float = np.sqrt(2), bias: float = 0.0) -> nn.Linear:
    nn.init.orthogonal_(layer.weight, std)
    nn.init.constant_(layer.bias, bias)
    return layer


class Agent(nn.Module):
    """CleanRL's continuous-action agent: Gaussian actor with a state-independent log-std."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: int) -> None:
        super().__init__()
        self.critic = nn.Sequential(
            layer_init(nn.Linear(obs_dim, hidden)),
            nn.Tanh(),
            layer_init(nn.Linear(hidden, hidden)),
            nn.Tanh(),
            layer_init(nn.Linear(hidden, 1), std=1.0),
        )
        self.actor_mean = nn.Sequential(
            layer_init(nn.Linear(obs_dim, hidden)),
            nn.Tanh(),
            layer_init(nn.Linear(hidden, hidden)),
            nn.Tanh(),
            layer_init(nn.Linear(hidden, act_dim), std=0.01),
        )
        self.actor_logstd = nn.Parameter(torch.full((1, act_dim), -0.5))

    def get_value(self, x: torch.Tensor) -> torch.Tensor:
        return self.critic(x).squeeze(-1)

    def get_action_and_value(self, x: torch.Tensor, action: torch.Tensor | None = None):
        mean = self.actor_mean(x)
        dist = Normal(mean, self.actor_logstd.expand_as(mean).exp())
        if action is None:
            action = dist.sample()
        return action, dist.log_prob(action).sum(-1), dist.entropy().sum(-1), self.get_value(x)


class ExportedActor(nn.Module):
    """The agent's actor as the exported policy contract: (M, dim) -> (M, 6) mean, log-std."""

    def __init__(self, agent: Agent) -> None:
        super().__init__()
        self.actor_mean, self.actor_logstd = agent.actor_mean, agent.actor_logstd

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        mean = self.actor_mean(obs)
        return torch.cat([mean, self.actor_logstd.expand_as(mean)], dim=-1)


def evaluated_scenario(args: argparse.Namespace) -> Scenario:
    """The task: ``--scenario`` with ``--duration`` (the training preset goes on top)."""
    scenario = resolve_scenario(args.scenario)
    if args.duration is not None:
        scenario = with_overrides(scenario, {"duration": args.duration})
    return scenario


def make_episodes(args: argparse.Namespace) -> FormationEpisodes:
    scenario = training_scenario(evaluated_scenario(args))
    return FormationEpisodes(scenario, batch_size=args.copies, autoreset=True)


def save_run(agent: Agent, scenario: Scenario, out: Path, sample: torch.Tensor) -> None:
    """The run directory ``uav-formation evaluate --policy OUT`` flies: the policy, scenario."""
    save_policy(ExportedActor(agent), out, sample.numpy(), observation=scenario.observation.kind)
    save_scenario(scenario, out / "scenario.yaml")


def main(argv: list[str] | None = None) -> dict[str, Any]:
    args = parse_args(argv)
    torch.manual_seed(args.seed)
    episodes = make_episodes(args)
    B, N, T = episodes.batch_size, episodes.n_uav, args.steps
    obs = torch.as_tensor(episodes.reset(seed=args.seed).observation)  # (B, N, obs_dim)
    agent = Agent(obs.shape[-1], 3, args.hidden)
    optimizer = torch.optim.Adam(agent.parameters(), lr=args.lr, eps=1e-5)
    before = [p.detach().clone() for p in agent.parameters()]

    buf_obs = torch.zeros((T, B, N, obs.shape[-1]))
    buf_act = torch.zeros((T, B, N, 3))
    buf_logp, buf_rew, buf_val = (torch.zeros((T, B, N)) for _ in range(3))
    buf_done = torch.zeros((T, B))
    episode_return = np.zeros((B, N))
    finished: list[float] = []  # per-agent returns of episodes that ended
    next_done = torch.zeros(B)
    start = time.perf_counter()
    for update in range(args.updates):
        for t in range(T):
            buf_obs[t], buf_done[t] = obs, next_done
            with torch.no_grad():
                action, logp, _, value = agent.get_action_and_value(obs)
            buf_act[t], buf_logp[t], buf_val[t] = action, logp, value
            step = episodes.step(action.numpy())  # clipped to [-1, 1] by the episode layer
            reward = torch.as_tensor(step.reward, dtype=torch.float32)
            if step.truncated.any():  # bootstrap time limits and divergence from V(final obs)
                final = torch.as_tensor(step.final_observation[step.truncated])
                with torch.no_grad():
                    reward[step.truncated] += args.gamma * agent.get_value(final)
            buf_rew[t] = reward
            episode_return += step.reward
            finished.extend(episode_return[step.done].ravel().tolist())
            episode_return[step.done] = 0.0
            obs = torch.as_tensor(step.observation)
            next_done = torch.as_tensor(step.done, dtype=torch.float32)

        # GAE over the per-agent streams; an episode end resets every agent of its copy
        with torch.no_grad():
            next_value = agent.get_value(obs)
            advantages = torch.zeros_like(buf_rew)
            last = torch.zeros((B, N))
            for t in reversed(range(T)):
                if t == T - 1:
                    nonterminal, value_next = 1.0 - next_done, next_value
                else:
                    nonterminal, value_next = 1.0 - buf_done[t + 1], buf_val[t + 1]
                nonterminal = nonterminal[:, None]
                delta = buf_rew[t] + args.gamma * value_next * nonterminal - buf_val[t]
                last = delta + args.gamma * args.gae_lambda * nonterminal * last
                advantages[t] = last
            returns = advantages + buf_val

        # flatten copies x agents: parameter sharing
        b_obs, b_act = buf_obs.reshape(-1, buf_obs.shape[-1]), buf_act.reshape(-1, 3)
        b_logp, b_adv = buf_logp.reshape(-1), advantages.reshape(-1)
        b_ret = returns.reshape(-1)
        batch = b_obs.shape[0]
        for _ in range(args.epochs):
            order = torch.randperm(batch)
            for lo in range(0, batch, args.minibatch):
                idx = order[lo : lo + args.minibatch]
                _, logp, entropy, value = agent.get_action_and_value(b_obs[idx], b_act[idx])
                ratio = (logp - b_logp[idx]).exp()
                adv = b_adv[idx]
                adv = (adv - adv.mean()) / (adv.std() + 1e-8)
                pg_loss = torch.max(
                    -adv * ratio, -adv * ratio.clamp(1 - args.clip, 1 + args.clip)
                ).mean()
                v_loss = 0.5 * ((value - b_ret[idx]) ** 2).mean()
                loss = pg_loss + args.vf_coef * v_loss - args.ent_coef * entropy.mean()
                optimizer.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(agent.parameters(), 0.5)
                optimizer.step()
        recent = np.mean(finished[-100:]) if finished else float("nan")
        if not args.quiet:
            print(
                f"update {update + 1}/{args.updates}: {T * B} steps x {N} agents, mean episode "
                f"return per UAV {recent:.4g} ({len(finished) // N} episodes), value loss "
                f"{v_loss.item():.3g}, {time.perf_counter() - start:.0f} s"
            )

    changed = any(not torch.equal(b, p) for b, p in zip(before, agent.parameters()))
    seconds = time.perf_counter() - start
    print(f"{args.updates} update(s) in {seconds:.1f} s; parameters changed: {changed}")
    out = Path(args.out)
    save_run(agent, training_scenario(evaluated_scenario(args)), out, b_obs[:64])
    recent = float(np.mean(finished[-100:])) if finished else None
    report = report_run(out, args.heldout_seeds, training_reward=recent, progress=not args.quiet)
    return {
        "returns": finished,
        "rewards": buf_rew.numpy(),
        "parameters_changed": changed,
        "seconds": seconds,
        "out": out,
        "heldout": report,
    }


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n")[0] + " Measured on a 2-core machine shared with other "
        "jobs: one default update (32 copies x 128 steps x 5 agents, one line each) took ~40 s, "
        "so the 200 default updates take hours; --quick ~15 s in all.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("--scenario", default="paper", help="registered name or YAML path")
    parser.add_argument("--copies", type=int, default=32, help="B, scenario copies")
    parser.add_argument("--steps", type=int, default=128, help="T, steps per rollout")
    parser.add_argument("--updates", type=int, default=200)
    parser.add_argument("--epochs", type=int, default=4)
    parser.add_argument("--minibatch", type=int, default=1024, help="agent-steps")
    parser.add_argument("--lr", type=float, default=3e-4)
    parser.add_argument("--gamma", type=float, default=0.99)
    parser.add_argument("--gae-lambda", type=float, default=0.95)
    parser.add_argument("--clip", type=float, default=0.2)
    parser.add_argument("--ent-coef", type=float, default=0.0)
    parser.add_argument("--vf-coef", type=float, default=0.5)
    parser.add_argument("--hidden", type=int, default=64)
    parser.add_argument("--duration", type=float, default=None, help="episode length [s]")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="runs/cleanrl_ppo", help="run directory")
    parser.add_argument(
        "--heldout-seeds", type=int, default=3, help="held-out seeds flown at the end (0: none)"
    )
    parser.add_argument("--quiet", action="store_true", help="no per-update lines, no bars")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="1 update of 8 copies x 32 steps, 20 s episodes: the smoke test",
    )
    args = parser.parse_args(argv)
    if args.quick:
        args.copies, args.steps, args.updates, args.epochs, args.minibatch = 8, 32, 1, 2, 256
        args.hidden = 32
        if args.duration is None:
            args.duration = 20.0
    return args


if __name__ == "__main__":
    main()
