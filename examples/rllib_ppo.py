"""RLlib (new API stack) PPO on the paper's scenario, one policy shared by the five UAVs.

RLlib's ``ParallelPettingZooEnv`` wraps ``parallel_env("paper", <training devices>)`` unpatched;
every agent maps to the one RLModule ``"shared"`` (parameter sharing). Training runs locally:
no remote env runners, a local learner, on the CPU.

RLlib lives in its own virtual environment (``ray[rllib]`` 2.60 pins gymnasium 1.2.2, the main
environment has gymnasium 1.4); ``bash tests/rllib/run.sh`` builds it and runs the smoke test.
By hand::

    python -m venv /work/venv-rllib && . /work/venv-rllib/bin/activate
    pip install torch==2.13.0 && pip install -e ".[rllib]"
    python examples/rllib_ppo.py --iterations 20
    python examples/rllib_ppo.py --quick        # one tiny iteration (what the smoke test runs)

The training devices of the episode layer (see docs/integrations.md) keep the returns in a
range PPO can learn from: the raw returns are -2e11..-4e12 per episode.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from typing import Any

# The episode layer's training devices: log-compressed reward, divergence truncation, corridor.
TRAINING_DEVICES: dict[str, Any] = {
    "episode__reward": "log1p",
    "episode__reward_scale": 100.0,
    "episode__max_formation_error": 100.0,
    "episode__max_velocity_error": 40.0,
    "episode__corridor_width": 200.0,
}
ENV_NAME = "uav_formation_paper"
MODULE_ID = "shared"


def make_env(env_config: dict[str, Any]):
    """RLlib's env creator: ``env_config`` holds ``scenario`` and the env overrides."""
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

    from uav_formation_env import parallel_env

    config = dict(env_config)
    scenario = config.pop("scenario", "paper")
    return ParallelPettingZooEnv(parallel_env(scenario, **config))


def build_config(args: argparse.Namespace):
    """The PPOConfig: one shared module, local sampling and learning."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec
    from ray.tune.registry import register_env

    register_env(ENV_NAME, make_env)
    env_config: dict[str, Any] = {"scenario": args.scenario, **TRAINING_DEVICES}
    if args.duration is not None:
        env_config["duration"] = args.duration
    hidden = [args.hidden, args.hidden]
    return (
        PPOConfig()
        .environment(ENV_NAME, env_config=env_config)
        .framework("torch")
        .env_runners(num_env_runners=0, num_envs_per_env_runner=1)
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


def main(argv: list[str] | None = None) -> dict[str, Any]:
    args = parse_args(argv)
    import numpy as np
    import ray

    if not ray.is_initialized():
        ray.init(
            num_cpus=args.num_cpus,
            include_dashboard=False,
            log_to_driver=False,
            object_store_memory=200 * 1024**2,
        )
    algo = build_config(args).build_algo()
    try:
        before = shared_parameters(algo)
        returns: list[float] = []
        start = time.perf_counter()
        for iteration in range(args.iterations):
            result = algo.train()
            runners = result.get("env_runners", {})
            ret = runners.get("episode_return_mean", math.nan)
            returns.append(float(ret))
            print(
                f"iteration {iteration + 1}: env steps {runners.get('num_env_steps_sampled', 0)}, "
                f"episodes {runners.get('num_episodes', 0)}, "
                f"mean episode return (5 UAVs) {ret:.4g}"
            )
        after = shared_parameters(algo)
        changed = any(not np.array_equal(before[k], after[k]) for k in before)
        seconds = time.perf_counter() - start
        print(f"{args.iterations} iteration(s) in {seconds:.1f} s; parameters changed: {changed}")
        return {"returns": returns, "parameters_changed": changed, "seconds": seconds}
    finally:
        logdir = getattr(algo, "logdir", None)
        algo.stop()
        if logdir and os.path.isdir(logdir) and not os.listdir(logdir):
            os.rmdir(logdir)  # the empty ~/ray_results/<date> folder of a run without loggers
        if args.shutdown:
            ray.shutdown()


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default="paper", help="registered name or YAML path")
    parser.add_argument("--iterations", type=int, default=10)
    parser.add_argument("--batch", type=int, default=4000, help="env steps per iteration")
    parser.add_argument("--minibatch", type=int, default=500)
    parser.add_argument("--epochs", type=int, default=10)
    parser.add_argument("--lr", type=float, default=3e-4)
    parser.add_argument("--hidden", type=int, default=64)
    parser.add_argument("--duration", type=float, default=None, help="episode length [s]")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--num-cpus", type=int, default=2)
    parser.add_argument(
        "--keep-ray", dest="shutdown", action="store_false", help="leave ray running at the end"
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="one tiny iteration (400 env steps, 40 s episodes): the smoke test",
    )
    args = parser.parse_args(argv)
    if args.quick:
        args.iterations, args.batch, args.minibatch, args.epochs = 1, 400, 200, 2
        args.hidden = 32
        if args.duration is None:
            args.duration = 40.0
    return args


if __name__ == "__main__":
    main()
