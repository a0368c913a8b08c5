"""RLlib PPO (new API stack) with one policy shared by every UAV, locally or on a Ray cluster.

    uav-formation train --algo rllib-ppo --iterations 20 --num-env-runners 2 --out runs/rllib
    uav-formation train --algo rllib-ppo --address auto ...      # an existing cluster
    uav-formation evaluate --policy runs/rllib --seeds 5

RLlib's ``ParallelPettingZooEnv`` wraps ``parallel_env(scenario, reward="train")`` unpatched:
the training task of :mod:`uav_formation_env.tasks` (docs/training.md), nothing RLlib-specific;
every agent maps to the one RLModule ``"shared"``. ``--num-env-runners K`` samples on K remote
env runners (Ray actors, one CPU each); 0 samples in the driver.

A run directory holds ``checkpoint/`` (RLlib's, to resume: ``--resume``), the shared actor as a
policy file (``policy.json`` + ``policy.npz``, :mod:`uav_formation_env.policies.policy_file`:
the Gaussian's mean, clipped to [-1, 1], is the deterministic action), ``scenario.yaml`` (the
scenario trained on: evaluation flies it under the evaluation's rules), ``progress.csv`` and
``config.yaml``. The policy needs only numpy: ``uav-formation evaluate --policy PATH`` runs it
without Ray or torch.

RLlib is the ``[rllib]`` extra in a virtual environment of its own (``ray[rllib]`` 2.60 pins
gymnasium 1.2.2); ``tests/rllib/run.sh`` builds one.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import shutil
import time
from pathlib import Path
from typing import Any

import yaml

from uav_formation_env.cli import OneLineParser, integer_at_least, positive_number
from uav_formation_env.config_io import resolve_scenario, save_scenario, with_overrides

ENV_NAME = "uav_formation"
MODULE_ID = "shared"


def make_env(env_config: dict[str, Any]):
    """RLlib's env creator: ``env_config`` holds ``scenario`` and the env overrides."""
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

    from uav_formation_env import parallel_env

    config = dict(env_config)
    scenario = config.pop("scenario", "paper")
    return ParallelPettingZooEnv(parallel_env(scenario, **config))


def build_config(args: argparse.Namespace):
    """The PPOConfig: one shared module, ``args.num_env_runners`` remote samplers."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec
    from ray.tune.registry import register_env

    register_env(ENV_NAME, make_env)
    env_config: dict[str, Any] = {"scenario": args.scenario, "reward": "train"}
    if args.duration is not None:
        env_config["duration"] = args.duration
    hidden = [args.hidden, args.hidden]
    return (
        PPOConfig()
        .environment(ENV_NAME, env_config=env_config)
        .framework("torch")
        .env_runners(num_env_runners=args.num_env_runners, num_envs_per_env_runner=1)
        .learners(num_learners=0)
        .multi_agent(
            policies={MODULE_ID},
            policy_mapping_fn=lambda agent_id, episode, **kwargs: MODULE_ID,
        )
        .rl_module(
            rl_module_spec=MultiRLModuleSpec(
                rl_module_specs={
                    MODULE_ID: RLModuleSpec(
                        model_config={"fcnet_hiddens": hidden, "vf_share_layers": False}
                    )
                }
            )
        )
        .training(
            train_batch_size_per_learner=args.batch,
            minibatch_size=args.minibatch,
            num_epochs=args.epochs,
            lr=args.lr,
            gamma=0.99,
            lambda_=0.95,
        )
        .debugging(seed=args.seed, log_level="ERROR")
    )


def shared_parameters(algo) -> dict[str, Any]:
    """A numpy copy of the shared module's parameters on the learner."""
    weights = algo.learner_group.get_weights(module_ids=[MODULE_ID])
    return {k: v.copy() for k, v in weights[MODULE_ID].items()}


def export_policy(algo, path: str | Path, obs_dim: int) -> Path:
    """The shared actor (its encoder and ``pi`` head, not the critic's) as a policy file in
    directory ``path``: (B, obs_dim) observations -> the Gaussian's mean, clipped."""
    import numpy as np
    import torch

    from uav_formation_baselines.torch_policy import save_policy

    module = algo.get_module(MODULE_ID)

    class Actor(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.module = module

        def forward(self, obs: torch.Tensor) -> torch.Tensor:
            return self.module.forward_inference({"obs": obs})["action_dist_inputs"]

    sample = np.random.default_rng(0).normal(size=(16, obs_dim)).astype(np.float32)
    exclude = ("critic", "vf")
    return save_policy(Actor().eval(), path, sample, observation="full", exclude=exclude)


def train(args: argparse.Namespace) -> dict[str, Any]:
    """Train, checkpoint and export (see the module docstring); returns a summary."""
    import numpy as np

    from uav_formation_env.core.local_observation import observation_size
    from uav_formation_env.distributed import ray_session
    from uav_formation_env.tasks import training_scenario

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {args.out!r} is a file; expected a directory")
    out.mkdir(parents=True, exist_ok=True)
    scenario = resolve_scenario(args.scenario)
    if args.duration is not None:
        scenario = with_overrides(scenario, {"duration": args.duration})
    with ray_session(args.address, num_cpus=args.num_cpus):
        algo = build_config(args).build_algo()
        checkpoint = out / "checkpoint"
        if args.resume:
            algo.restore(str(checkpoint.resolve()))
        try:
            before = shared_parameters(algo)
            rows, start = [], time.perf_counter()
            for iteration in range(args.iterations):
                result = algo.train()
                runners = result.get("env_runners", {})
                row = {  # plain floats: RLlib reports numpy scalars
                    "iteration": iteration + 1,
                    "env_steps": float(runners.get("num_env_steps_sampled_lifetime", math.nan)),
                    "episodes": float(runners.get("num_episodes_lifetime", math.nan)),
                    "episode_return_mean": float(runners.get("episode_return_mean", math.nan)),
                    "seconds": round(time.perf_counter() - start, 3),
                }
                rows.append(row)
                if not args.quiet:
                    print(
                        f"iteration {row['iteration']}: return {row['episode_return_mean']:.4g} "
                        f"(5 UAVs, transformed reward), {row['seconds']:.1f} s"
                    )
            changed = any(
                not np.array_equal(value, shared_parameters(algo)[key])
                for key, value in before.items()
            )
            if checkpoint.exists():
                shutil.rmtree(checkpoint)
            algo.save(str(checkpoint.resolve()))
            export_policy(algo, out, observation_size(training_scenario(scenario)))
        finally:
            logdir = getattr(algo, "logdir", None)
            algo.stop()
            if logdir and os.path.isdir(logdir) and not os.listdir(logdir):
                os.rmdir(logdir)  # the empty folder of a run without loggers
    save_scenario(training_scenario(scenario), out / "scenario.yaml")
    with open(out / "progress.csv", "w", newline="", encoding="utf-8") as stream:
        writer = csv.DictWriter(stream, fieldnames=list(rows[0]) if rows else ["iteration"])
        writer.writeheader()
        writer.writerows(rows)
    summary = {
        "algo": "rllib-ppo",
        "scenario": scenario.name,
        "iterations": args.iterations,
        "num_env_runners": args.num_env_runners,
        "reward": "train",
        "returns": [row["episode_return_mean"] for row in rows],
        "parameters_changed": bool(changed),
        "seconds": rows[-1]["seconds"] if rows else 0.0,
    }
    with open(out / "config.yaml", "w", encoding="utf-8") as stream:
        yaml.safe_dump({**summary, "args": vars(args)}, stream, sort_keys=False)
    print(f"wrote the policy {out}, {checkpoint}, progress.csv, scenario.yaml")
    return summary


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="uav-formation train --algo rllib-ppo",
        description=__doc__.split("\n")[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("--algo", choices=["rllib-ppo"], default="rllib-ppo")
    parser.add_argument("--out", default="runs/rllib", help="run directory")
    parser.add_argument("--scenario", default="paper", help="registered name or YAML path")
    parser.add_argument("--iterations", type=integer_at_least(1), default=10)
    parser.add_argument(
        "--num-env-runners", type=integer_at_least(0), default=0, help="remote samplers"
    )
    parser.add_argument("--address", default=None, help="Ray cluster (None: a local instance)")
    parser.add_argument(
        "--num-cpus", type=integer_at_least(1), default=None, help="CPUs of a local instance"
    )
    parser.add_argument("--batch", type=integer_at_least(1), default=4000, help="env steps/iter")
    parser.add_argument("--minibatch", type=integer_at_least(1), default=500)
    parser.add_argument("--epochs", type=integer_at_least(1), default=10)
    parser.add_argument("--lr", type=positive_number, default=3e-4)
    parser.add_argument("--hidden", type=integer_at_least(1), default=64)
    parser.add_argument("--duration", type=positive_number, default=None, help="episode [s]")
    parser.add_argument("--seed", type=integer_at_least(0), default=0)
    parser.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint")
    parser.add_argument("--quiet", action="store_true")
    parser.add_argument(
        "--quick", action="store_true", help="one tiny iteration (the smoke test's size)"
    )
    parser.add_argument(
        "--heldout-seeds",
        type=integer_at_least(0),
        default=3,
        help="held-out seeds (0, 1, ...) flown at the end by the policy and LFPIO (0: none)",
    )
    return parser


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    args = build_parser().parse_args(argv)
    if args.quick:
        args.iterations, args.batch, args.minibatch, args.epochs, args.hidden = 1, 400, 200, 2, 32
        if args.duration is None:
            args.duration = 40.0
    return args


def main(argv: list[str] | None = None) -> int:
    from uav_formation_env.evaluation.heldout import report_run

    args = parse_args(argv)
    summary = train(args)
    returns = [r for r in summary["returns"] if math.isfinite(r)]
    reward = returns[-1] if returns else None  # RLlib's: the 5 UAVs' summed episode return
    report_run(args.out, args.heldout_seeds, training_reward=reward, progress=not args.quiet)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
