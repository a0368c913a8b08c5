"""A fast on-policy trainer (CleanRL ``ppo_continuous_action`` style) that steps the batched
episode layer in-process: PPO with parameter sharing, MAPPO (centralised critic) and IPPO.

    python -m uav_formation_baselines.onpolicy --algo ppo --task paper --seed 0 --frames 2e6 \
        --copies 256 --out runs/ppo_paper [--device cpu|cuda] [--eval-every 10] [--eval-seeds 8] \
        [--set key=value ...] [--init DIR [--init-member K] [--init-reg COEF]] [--resume]

Frames are agent-steps: one control step of B copies of N UAVs is B N frames. The reward is
``step.reward`` of :class:`~uav_formation_env.episode.FormationEpisodes` as the scenario defines
it; a copy truncated (not terminated) has ``gamma V(final observation)`` added to its last reward.
On ``--device cpu`` the episode layer runs on numpy, on ``cuda`` on torch tensors of that device.

The run directory holds ``policy.json`` + ``policy.npz`` (the learned-policy file format, written
at each evaluation, at the end and on Ctrl-C), ``checkpoint.pt`` (state dicts, for ``--init``),
``config.yaml`` (every hyper-parameter, the scenario and the run's metadata), ``scenario.yaml``
and ``progress.csv`` (one row per update: frames, training wall and CPU time without the
evaluations, agent-steps/s, mean reward per agent-step of the rollout, mean return and length of
the last 200 finished episodes; the evaluation columns filled at evaluations: completed missions,
route error max, collisions after t = 0 and the realised J per UAV on the held-out seeds).

Modules: :mod:`.onpolicy_trainer` (rollout, GAE, update, evaluation, saves),
:mod:`.onpolicy_nets` (networks), :mod:`.onpolicy_io` (policy files), :mod:`.onpolicy_config`
(hyper-parameters, ``baselines/hyperparams/onpolicy.yml``).
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
from pathlib import Path

from uav_formation_baselines.config import parse_set
from uav_formation_baselines.onpolicy_config import ONPOLICY_ALGOS, load_config
from uav_formation_baselines.onpolicy_trainer import OnPolicyTrainer, build_scenario
from uav_formation_env.cli import OneLineParser, integer_at_least
from uav_formation_env.evaluation.heldout import HELDOUT_SEEDS, report_run

PROG = "python -m uav_formation_baselines.onpolicy"


def build_parser(prog: str = PROG) -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog=prog,
        description="Train PPO (shared), MAPPO or IPPO on the batched episode layer in-process, "
        "on the training task (docs/training.md, which gives the measured durations).",
    )
    parser.add_argument("--algo", choices=ONPOLICY_ALGOS, required=True)
    parser.add_argument(
        "--task",
        default="paper",
        help="registered scenario name or YAML path; a comma-separated list (hold,track,paper) "
        "is a curriculum: the copies move to the next task after an evaluation that completes "
        "promote_at of its missions with its mean route error max <= promote_route_error",
    )
    parser.add_argument("--seed", type=integer_at_least(0), default=0)
    parser.add_argument(
        "--frames", type=_frames, required=True, help="agent-steps (B N per control step), e.g. 2e6"
    )
    parser.add_argument(
        "--copies", type=integer_at_least(1), default=None, help="scenario copies B"
    )
    parser.add_argument("--out", required=True, help="run directory")
    parser.add_argument("--device", default="cpu", help="cpu (numpy episodes) or cuda[:k]")
    parser.add_argument(
        "--backend", choices=("numpy", "torch"), default=None,
        help="the episode layer's arrays (default: numpy on cpu, torch on cuda)",
    )  # fmt: skip
    parser.add_argument("--eval-every", type=integer_at_least(0), default=None, help="updates")
    parser.add_argument("--eval-seeds", type=integer_at_least(1), default=None)
    parser.add_argument(
        "--init", default=None, help="run or policy directory to start from (fine-tuning)"
    )
    parser.add_argument(
        "--resume", action="store_true",
        help="continue the run in --out (its checkpoint.pt) up to --frames",
    )  # fmt: skip
    parser.add_argument("--init-reg", type=float, default=None, help="L2 pull to the --init actor")
    parser.add_argument(
        "--init-member",
        type=integer_at_least(0),
        default=None,
        help="the network of an ensemble --init (a shipped DAgger student) to start from",
    )
    parser.add_argument(
        "--set", dest="overrides", action="extend", nargs="+", default=[], metavar="KEY=VALUE",
        help="hyper-parameter override (YAML value); env.<scenario key>=... overrides the task",
    )  # fmt: skip
    parser.add_argument("--hyperparams", default=None, help="YAML file (default: shipped)")
    parser.add_argument(
        "--heldout-seeds",
        type=integer_at_least(0),
        default=len(HELDOUT_SEEDS),
        help="held-out seeds (0, 1, ...) flown at the end by the policy and LFPIO (0: none)",
    )
    parser.add_argument("--no-progress", action="store_true")
    return parser


def _frames(text: str) -> int:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of frames, got {text!r}") from None
    if not math.isfinite(value) or value < 1:
        raise argparse.ArgumentTypeError(f"expected frames >= 1, got {text!r}")
    return int(value)


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def main(argv: list[str] | None = None, prog: str | None = None) -> int:
    """Command-line entry point; returns the exit code."""
    args = build_parser(prog or PROG).parse_args(argv)
    overrides = parse_set(args.overrides)
    for key, value in (
        ("copies", args.copies),
        ("eval_every", args.eval_every),
        ("eval_seeds", args.eval_seeds),
        ("init_reg", args.init_reg),
    ):
        if value is not None:
            overrides[key] = value
    try:
        config = load_config(args.algo, overrides, args.hyperparams)
        # "hold,track,paper": a curriculum up the task ladder (uav_formation_env.tasks.LADDER)
        scenario, *ladder = [build_scenario(task, config) for task in args.task.split(",")]
        trainer = OnPolicyTrainer(
            args.algo,
            scenario,
            config,
            args.seed,
            args.frames,
            args.out,
            args.device,
            args.init,
            args.backend,
            args.resume,
            ladder,
            args.init_member,
        )
    except ValueError as error:
        print(f"uav-formation: error: {error}", file=sys.stderr)
        return 2
    previous = signal.signal(signal.SIGTERM, _interrupt)  # a killed run saves like a Ctrl-C
    try:
        result = trainer.train(progress=not args.no_progress)
    finally:
        signal.signal(signal.SIGTERM, previous)
    fps = result["frames"] / max(result["wall_time_s"], 1e-9)
    per_cpu = result["frames"] / max(result["cpu_time_s"], 1e-9)
    print(
        f"{args.algo}: {result['frames']} frames in {result['wall_time_s']:.0f} s "
        f"({fps:.0f} agent-steps/s; {per_cpu:.0f} per CPU-second); "
        f"eval {result.get('eval_completed', '-')}/{result.get('eval_episodes', '-')} completed, "
        f"J {result.get('eval_J', float('nan')):.4g}; wrote {args.out}"
    )
    reward = float(result.get("eval_return", float("nan")))
    report_run(args.out, args.heldout_seeds, training_reward=reward)
    best = Path(args.out) / "best"
    if best.is_dir():  # the policy of the best evaluation on the last task (keep_best)
        report_run(best, args.heldout_seeds)
    return 0


if __name__ == "__main__":
    sys.exit(main())
