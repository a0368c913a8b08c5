"""stable-baselines3 PPO with one policy shared by all UAVs, on the batched VecEnv.

``uav_formation_env.vec_env("paper", num_copies=B, reward="train")`` is an SB3 ``VecEnv``
with one entry per (copy, agent): B x 5 entries, every UAV of every copy a separate environment of
the one shared policy (parameter sharing). ``VecMonitor`` records each entry's episode return
(one UAV's).

    pip install torch==2.13.0 && pip install -e ".[rl]"
    python examples/sb3_ppo.py --timesteps 200000 --out runs/sb3_ppo
    python examples/sb3_ppo.py --quick --out /tmp/sb3_ppo   # 1280 agent-steps (the smoke test)
    uav-formation evaluate --policy runs/sb3_ppo --seeds 10

The run directory holds ``model.zip`` and ``scenario.yaml`` (the scenario as evaluated); the run
ends with the mission on held-out seeds beside LFPIO's
(:func:`uav_formation_env.evaluation.heldout.report_run`).

The training task (``reward="train"``, docs/training.md) keeps the rewards at a few
units per step (the raw returns are -2e11..-4e12 per episode). For the full recipe used for the
shipped baselines (VecNormalize, staggered starts), see ``python -m uav_formation_baselines.train``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecMonitor

from uav_formation_env import vec_env
from uav_formation_env.config import Scenario
from uav_formation_env.config_io import resolve_scenario, save_scenario, with_overrides
from uav_formation_env.evaluation.heldout import report_run
from uav_formation_env.tasks import training_scenario


def main(argv: list[str] | None = None) -> dict[str, Any]:
    args = parse_args(argv)
    scenario = resolve_scenario(args.scenario)  # the task (the training preset goes on top)
    if args.duration is not None:
        scenario = with_overrides(scenario, {"duration": args.duration})
    env = VecMonitor(vec_env(scenario, num_copies=args.copies, reward="train"))
    model = PPO(
        "MlpPolicy",
        env,
        n_steps=args.n_steps,
        batch_size=args.batch_size,
        n_epochs=args.epochs,
        learning_rate=args.lr,
        policy_kwargs={"net_arch": [args.hidden, args.hidden]},
        seed=args.seed,
        device="cpu",
        verbose=args.verbose,
    )
    before = [p.detach().clone() for p in model.policy.parameters()]
    start = time.perf_counter()
    model.learn(total_timesteps=args.timesteps, progress_bar=not args.quiet)
    seconds = time.perf_counter() - start
    returns = [float(info["r"]) for info in model.ep_info_buffer]  # per UAV
    changed = any(not torch.equal(b, p) for b, p in zip(before, model.policy.parameters()))
    mean = np.mean(returns) if returns else float("nan")
    print(
        f"{model.num_timesteps} agent-steps in {seconds:.1f} s; mean episode return per UAV "
        f"{mean:.4g} over the last {len(returns)} episodes; parameters changed: {changed}"
    )
    env.close()
    out = Path(args.out)
    save_run(model, training_scenario(scenario), out)
    report = report_run(out, args.heldout_seeds, training_reward=mean, progress=not args.quiet)
    return {
        "returns": returns,
        "parameters_changed": changed,
        "seconds": seconds,
        "out": out,
        "heldout": report,
    }


def save_run(model: PPO, scenario: Scenario, out: Path) -> None:
    """The run directory ``uav-formation evaluate --policy OUT`` flies: the model, the scenario."""
    out.mkdir(parents=True, exist_ok=True)
    model.save(out / "model.zip")
    save_scenario(scenario, out / "scenario.yaml")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n")[0] + " Measured on a 2-core machine shared with other "
        "jobs: --quick 16 s in all; the defaults (5000 agent-steps) train in seconds, then the "
        "held-out flights of 200 s episodes take ~15 s.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("--scenario", default="paper", help="registered name or YAML path")
    parser.add_argument("--copies", type=int, default=8, help="B, scenario copies (x 5 entries)")
    parser.add_argument("--timesteps", type=int, default=5000, help="agent-steps")
    parser.add_argument("--n-steps", type=int, default=128, help="steps per entry per rollout")
    parser.add_argument("--batch-size", type=int, default=256)
    parser.add_argument("--epochs", type=int, default=10)
    parser.add_argument("--lr", type=float, default=3e-4)
    parser.add_argument("--hidden", type=int, default=64)
    parser.add_argument("--duration", type=float, default=None, help="episode length [s]")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="runs/sb3_ppo", help="run directory")
    parser.add_argument(
        "--heldout-seeds", type=int, default=3, help="held-out seeds flown at the end (0: none)"
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.add_argument("--verbose", type=int, default=0, help="SB3's log tables (1)")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="2 copies x 5 UAVs x 64 steps x 2 rollouts, 20 s episodes: the smoke test",
    )
    args = parser.parse_args(argv)
    if args.quick:
        args.copies, args.n_steps, args.timesteps = 2, 64, 1280
        args.batch_size, args.epochs, args.hidden = 128, 2, 32
        if args.duration is None:
            args.duration = 20.0
    return args


if __name__ == "__main__":
    main()
