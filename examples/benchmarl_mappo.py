"""BenchMARL MAPPO on the paper's scenario, through the shipped task class.

``uav_formation_baselines.benchmarl_task.UavFormationTask.PAPER`` is a BenchMARL task (one group
``"uav"``, continuous actions, the global state for the centralised critic, the training preset
on by default); any other registered scenario is another member (``.N3``, ``.WINDY``, ...) and a
YAML scenario goes through ``uav_formation_task("file.yaml")``.

    pip install torch==2.13.0 && pip install -e ".[benchmarl]"
    python examples/benchmarl_mappo.py --iterations 100 --out runs/benchmarl_mappo
    python examples/benchmarl_mappo.py --quick --out /tmp/benchmarl   # one tiny iteration on CPU
    uav-formation evaluate --policy runs/benchmarl_mappo --seeds 10

The run directory holds ``policy.json`` + ``policy.npz`` (the shared actor, exported as the
BenchMARL recipe does: :func:`uav_formation_baselines.benchmarl_train.export_actor`),
``scenario.yaml`` and BenchMARL's experiment folder ``benchmarl/``; the run ends with the mission on
held-out seeds beside LFPIO's
(:func:`uav_formation_env.evaluation.heldout.report_run`). No BenchMARL evaluation, rendering or
network logger by default (``--loggers csv`` writes CSV files under ``--out``).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

import torch
from benchmarl.algorithms import MappoConfig
from benchmarl.experiment import Experiment, ExperimentConfig
from benchmarl.models.mlp import MlpConfig

from uav_formation_baselines.benchmarl_task import UavFormationTask, uav_formation_task
from uav_formation_baselines.benchmarl_train import export_actor
from uav_formation_env.config_io import save_scenario
from uav_formation_env.envs import resolve_with_overrides
from uav_formation_env.episode import FormationEpisodes
from uav_formation_env.evaluation.heldout import report_run


def make_experiment(args: argparse.Namespace, out: Path) -> Experiment:
    config = ExperimentConfig.get_from_yaml()  # BenchMARL's defaults, then ours
    config.sampling_device = config.train_device = config.buffer_device = "cpu"
    config.max_n_iters, config.max_n_frames = args.iterations, None
    config.on_policy_collected_frames_per_batch = args.frames_per_batch
    config.on_policy_n_envs_per_worker = args.envs
    config.on_policy_minibatch_size = args.minibatch
    config.on_policy_n_minibatch_iters = args.minibatch_iters
    config.lr = args.lr
    config.evaluation = False
    config.render = False
    config.loggers = list(args.loggers)
    config.create_json = False
    config.checkpoint_interval = 0
    config.checkpoint_at_end = False
    config.save_folder = str(out)

    task_options: dict[str, Any] = {"backend": args.backend}
    if args.duration is not None:
        task_options["duration"] = args.duration
    if args.scenario.endswith((".yaml", ".yml")):
        task = uav_formation_task(args.scenario, **task_options)
    else:
        task = UavFormationTask[args.scenario.upper()].get_task(task_options)

    model = MlpConfig(
        num_cells=[args.hidden, args.hidden],
        activation_class=torch.nn.Tanh,
        layer_class=torch.nn.Linear,
    )
    return Experiment(
        task=task,
        algorithm_config=MappoConfig.get_from_yaml(),
        model_config=model,
        critic_model_config=model,
        seed=args.seed,
        config=config,
    )


def save_run(experiment: Experiment, out: Path) -> None:
    """The run directory ``uav-formation evaluate --policy OUT`` flies: the policy, scenario."""
    settings = experiment.task.settings
    scenario = resolve_with_overrides(settings.scenario, settings.scenario_overrides())
    save_scenario(scenario, out / "scenario.yaml")
    sample = FormationEpisodes(scenario, 2).reset(seed=[0, 1]).observation
    export_actor(experiment, out, sample.reshape(-1, sample.shape[-1]))


def main(argv: list[str] | None = None) -> dict[str, Any]:
    args = parse_args(argv)
    out = Path(args.out)
    (out / "benchmarl").mkdir(parents=True, exist_ok=True)
    experiment = make_experiment(args, out / "benchmarl")
    before = [p.detach().clone() for p in experiment.policy.parameters()]
    start = time.perf_counter()
    experiment.run()
    seconds = time.perf_counter() - start
    changed = any(not torch.equal(b, p) for b, p in zip(before, experiment.policy.parameters()))
    mean_return = float(experiment.mean_return)
    print(
        f"{experiment.n_iters_performed} iteration(s), {experiment.total_frames} frames in "
        f"{seconds:.1f} s; mean episode return per UAV {mean_return:.4g}; "
        f"policy parameters changed: {changed}"
    )
    save_run(experiment, out)
    reward = mean_return if math.isfinite(mean_return) else None
    report = report_run(out, args.heldout_seeds, training_reward=reward, progress=not args.quiet)
    return {
        "mean_return": mean_return,
        "finite": math.isfinite(mean_return),
        "iterations": experiment.n_iters_performed,
        "parameters_changed": changed,
        "seconds": seconds,
        "out": out,
        "heldout": report,
    }


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n")[0] + " Each default iteration collects 30x the frames "
        "of --quick's one (6000, BenchMARL's progress bar); 50 of them take hours on a CPU. "
        "--quick took ~40 s in all on a 2-core machine shared with other jobs.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument(
        "--scenario", default="paper", help="registered name (paper, n3, ...) or a YAML path"
    )
    parser.add_argument("--iterations", type=int, default=50)
    parser.add_argument("--frames-per-batch", type=int, default=6000, help="env steps")
    parser.add_argument("--envs", type=int, default=10, help="env copies per collector")
    parser.add_argument("--minibatch", type=int, default=400)
    parser.add_argument("--minibatch-iters", type=int, default=45)
    parser.add_argument("--lr", type=float, default=5e-5)
    parser.add_argument("--hidden", type=int, default=256)
    parser.add_argument("--duration", type=float, default=None, help="episode length [s]")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--backend",
        choices=("pettingzoo", "torch"),
        default="pettingzoo",
        help="the task's env: PettingZoo copies, or one batched torch env (CPU or GPU)",
    )
    parser.add_argument("--loggers", nargs="*", default=[], help="e.g. csv tensorboard")
    parser.add_argument("--out", default="runs/benchmarl_mappo", help="run directory")
    parser.add_argument(
        "--heldout-seeds", type=int, default=3, help="held-out seeds flown at the end (0: none)"
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bars at the end")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="1 iteration of 200 frames (2 envs), 20 s episodes: the smoke test",
    )
    args = parser.parse_args(argv)
    if args.quick:
        args.iterations, args.frames_per_batch, args.envs = 1, 200, 2
        args.minibatch, args.minibatch_iters, args.hidden = 100, 4, 32
        if args.duration is None:
            args.duration = 20.0
    return args


if __name__ == "__main__":
    main()
