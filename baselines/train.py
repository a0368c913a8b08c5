"""Train PPO or SAC with one policy shared by every UAV (parameter sharing).

    python -m uav_formation_baselines.train --algo ppo --timesteps 1000000 --out runs/ppo_paper \
        [--scenario paper] [--seed 0] [--copies 8] [--threads 1] [--set key=value ...]

Timesteps are *agent*-timesteps: SB3's ``num_timesteps``, which counts every (copy, agent) entry of
the :class:`~uav_formation_env.envs.vector.FormationVecEnv`, so one control step of B copies of the
paper's 5 UAVs is 5 B timesteps (PPO rounds up to whole rollouts of n_steps x 5 B).

The output directory holds ``model.zip``, ``obs_stats.npz`` (load both with ``uav-formation evaluate
--policy DIR``) and ``vecnormalize.pkl`` (to resume), ``heldout.json`` (the mission on held-out
seeds beside LFPIO's, printed at the end: :func:`uav_formation_env.evaluation.heldout.
heldout_report`), ``config.yaml`` (resolved hyper-parameters, scenario, seed, timesteps, wall
time), ``scenario.yaml`` (the scenario trained on, with its episode options; evaluation
flies it under :func:`uav_formation_env.tasks.evaluation_scenario`'s rules), ``progress.csv``
and ``tensorboard/`` (SB3 logger), and with evaluation on ``evaluations.csv`` and ``best/``
(model and statistics of the best evaluation), with checkpoints on ``checkpoints/<steps>/``.

The run is written beside ``--out`` and moved into place when it ends
(:mod:`uav_formation_env.run_folder`): a non-empty ``--out`` needs ``--overwrite``. Ctrl-C
(SIGINT) ends training early and saves the model reached, with ``interrupted: true`` in
``config.yaml``; a second Ctrl-C while saving leaves ``--out`` as it was.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from uav_formation_baselines import ALGOS
from uav_formation_baselines.config import (
    apply_overrides,
    load_hyperparams,
    parse_set,
    split_params,
)
from uav_formation_env.cli import OneLineParser, integer_at_least, on_terminal
from uav_formation_env.config import Scenario
from uav_formation_env.config_io import SCENARIOS, resolve_scenario, save_scenario
from uav_formation_env.evaluation.heldout import HELDOUT_SEEDS
from uav_formation_env.run_folder import run_folder


def scenario_key(scenario: str | Path | Scenario) -> str:
    """The hyper-parameter section of a scenario: its registered name, else ``Scenario.name``."""
    if isinstance(scenario, str) and scenario in SCENARIOS:
        return scenario
    return resolve_scenario(scenario).name


def algorithm_class(algo: str) -> type:
    """The stable-baselines3 class of ``"ppo"`` or ``"sac"``."""
    from stable_baselines3 import PPO, SAC

    classes = {"ppo": PPO, "sac": SAC}
    if algo.lower() not in classes:
        raise ValueError(f"unknown algorithm {algo!r}; expected one of {list(ALGOS)}")
    return classes[algo.lower()]


def _logger(out: Path, stdout: bool):
    from stable_baselines3.common.logger import Logger, make_output_format

    formats = [make_output_format("csv", str(out))]
    formats.append(make_output_format("tensorboard", str(out / "tensorboard")))
    if stdout:
        formats.append(make_output_format("stdout", str(out)))
    return Logger(folder=str(out), output_formats=formats)


def train(
    algo: str,
    timesteps: int,
    out: str | Path,
    scenario: str | Path | Scenario = "paper",
    seed: int = 0,
    copies: int | None = None,
    threads: int = 1,
    overrides: Mapping[str, Any] | None = None,
    hyperparams: str | Path | None = None,
    progress: bool = True,
    stdout_log: bool = False,
    overwrite: bool = False,
) -> dict[str, Any]:
    """Train one run and save it to ``out`` (see the module docstring); returns its config.

    Args:
        algo: ``"ppo"`` or ``"sac"``.
        timesteps: agent-timesteps (every (copy, agent) entry counts).
        out: output directory (created).
        scenario: registered name, YAML path or Scenario.
        seed: seed of the model (torch, numpy) and of the training copies (copy b: seed + b).
        copies: scenario copies B (None: the hyper-parameter file's ``copies``).
        threads: torch CPU threads.
        overrides: nested hyper-parameter overrides (as from ``--set``).
        hyperparams: YAML file (None: ``baselines/hyperparams/<algo>.yml``).
        progress: show a progress bar.
        stdout_log: also print SB3's log tables.
        overwrite: replace an earlier run at ``out``.
    """
    import torch

    torch.set_num_threads(int(threads))
    cls = algorithm_class(algo)
    key = scenario_key(scenario)
    scen = resolve_scenario(scenario)
    params = load_hyperparams(algo, key, hyperparams)
    params = apply_overrides(params, overrides or {})
    if copies is not None:
        params["copies"] = int(copies)
    training, algo_kwargs = split_params(params, cls)
    with run_folder(out, overwrite=overwrite, command="train") as folder:
        model, base, wall, interrupted = _learn(
            cls, scen, training, algo_kwargs, folder, timesteps, seed, progress, stdout_log
        )
        config = {
            "algo": algo.lower(),
            "scenario": key,
            "seed": int(seed),
            "timesteps_requested": int(timesteps),
            "timesteps": int(model.num_timesteps),
            "interrupted": interrupted,
            "num_envs": int(base.num_envs),
            "wall_time_s": round(wall, 2),
            "agent_steps_per_s": round(model.num_timesteps / max(wall, 1e-9), 1),
            "torch_threads": int(threads),
            "hyperparams": params,
            "versions": _versions(),
        }
        with open(folder / "config.yaml", "w", encoding="utf-8") as stream:
            yaml.safe_dump(config, stream, sort_keys=False)
    return config


def _learn(cls, scen, training, algo_kwargs, out, timesteps, seed, progress, stdout_log):
    """Train a model into the run folder ``out``; Ctrl-C ends training and saves the model
    reached. Returns (model, training VecEnv, wall time [s], interrupted)."""
    from uav_formation_baselines.callbacks import (
        CheckpointCallback,
        FormationEvalCallback,
        save_run,
    )
    from uav_formation_baselines.wrappers import make_training_env, training_scenario

    trained = training_scenario(scen, training)
    env, base = make_training_env(scen, training, gamma=float(algo_kwargs.get("gamma", 0.99)))
    model = cls(training["policy"], env, seed=seed, device="cpu", verbose=0, **algo_kwargs)
    model.set_logger(_logger(out, stdout_log))
    callbacks = []
    if training["eval_freq"]:
        callbacks.append(
            FormationEvalCallback(
                trained,
                training["eval_seeds"],
                training["eval_freq"],
                out,
                training["eval_duration"],
            )
        )
    if training["checkpoint_freq"]:
        callbacks.append(CheckpointCallback(training["checkpoint_freq"], out))

    start = time.perf_counter()
    interrupted = False
    try:
        model.learn(total_timesteps=int(timesteps), callback=callbacks, progress_bar=progress)
    except KeyboardInterrupt:
        interrupted = True  # save the model reached; the run folder is still moved into place
    wall = time.perf_counter() - start
    save_run(model, out)
    save_scenario(trained, out / "scenario.yaml")
    model.logger.close()  # its files are complete before the folder moves into place
    env.close()
    return model, base, wall, interrupted


def _versions() -> dict[str, str]:
    import stable_baselines3
    import torch

    return {
        "python": platform.python_version(),
        "torch": str(torch.__version__),
        "stable_baselines3": str(stable_baselines3.__version__),
    }


TRAIN_DESCRIPTION = """\
Train one policy shared by all UAVs and save a run directory that
`uav-formation evaluate --policy OUT` flies; at the end the policy and LFPIO fly
--heldout-seeds held-out seeds (0, 1, ...) and the mission is printed beside the
training reward.

--algo ppo / sac: stable-baselines3 over the batched VecEnv (the [rl] extra), with one
evaluation (4 episodes) every eval_freq agent-steps and held-out flights at the end:
--timesteps 20000 takes 15-25 s in all on one core. SAC is ~5x slower per agent-step.
--algo rllib-ppo: RLlib in its own virtual environment (ray[rllib] pins gymnasium 1.2.2);
see `uav-formation train --algo rllib-ppo --help`."""


def build_parser(
    prog: str = "python -m uav_formation_baselines.train", algos: tuple[str, ...] = ALGOS
) -> argparse.ArgumentParser:
    """The SB3 trainer's options; ``algos``: the ``--algo`` choices shown (the CLI lists every
    trainer it dispatches to)."""
    parser = OneLineParser(
        prog=prog,
        description=TRAIN_DESCRIPTION,
        formatter_class=TrainHelpFormatter,
    )
    parser.add_argument("--algo", choices=algos, required=True, help="the trainer")
    parser.add_argument(
        "--timesteps",
        type=integer_at_least(1),
        required=True,
        help="agent-timesteps: SB3's num_timesteps, counting every (copy, agent) entry, so one "
        "control step of B copies of N UAVs is B*N timesteps",
    )
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument("--scenario", default="paper", help="registered name or YAML path")
    parser.add_argument("--seed", type=integer_at_least(0), default=0)
    parser.add_argument(
        "--copies", type=integer_at_least(1), default=None, help="scenario copies B"
    )
    parser.add_argument("--threads", type=integer_at_least(1), default=1, help="torch threads")
    parser.add_argument(
        "--set",
        dest="overrides",
        action="extend",
        nargs="+",
        default=[],
        metavar="KEY=VALUE",
        help="hyper-parameter override, value as YAML; dotted keys reach into mappings "
        "(e.g. learning_rate=1e-4 policy_kwargs.net_arch=[256,256])",
    )
    parser.add_argument("--hyperparams", default=None, help="YAML file (default: shipped)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--log-stdout", action="store_true", help="print SB3's log tables")
    parser.add_argument(
        "--heldout-seeds",
        type=integer_at_least(0),
        default=len(HELDOUT_SEEDS),
        help="held-out seeds (0, 1, ...) flown at the end by the policy and LFPIO (0: none)",
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an earlier run at --out")
    return parser


class TrainHelpFormatter(
    argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter
):
    """Defaults in every option's help, the description as written."""


def training_reward(progress_csv: Path) -> float | None:
    """The last ``rollout/ep_rew_mean`` of SB3's ``progress.csv`` (the transformed, normalised
    reward of one UAV's episode), or None if no episode ended."""
    import csv

    if not progress_csv.is_file():
        return None
    with open(progress_csv, newline="", encoding="utf-8") as stream:
        values = [row.get("rollout/ep_rew_mean") for row in csv.DictReader(stream)]
    values = [float(v) for v in values if v not in (None, "")]
    return values[-1] if values else None


def report_heldout(out: Path, seeds: int, progress: bool = True):
    """The held-out mission of the saved run (:func:`~uav_formation_env.evaluation.heldout.
    report_run`) beside its last training reward."""
    from uav_formation_env.evaluation.heldout import report_run

    reward = training_reward(out / "progress.csv")
    return report_run(out, seeds, training_reward=reward, progress=progress)


def main(
    argv: list[str] | None = None,
    prog: str = "python -m uav_formation_baselines.train",
    algos: tuple[str, ...] = ALGOS,
) -> int:
    """Command-line entry point; returns the exit code."""
    from uav_formation_env.extras import require

    args = build_parser(prog, algos).parse_args(None if argv is None else list(argv))
    if args.algo not in ALGOS:
        raise ValueError(f"--algo {args.algo} is not a stable-baselines3 algorithm {ALGOS}")
    require("stable_baselines3", f"{prog} --algo {args.algo}")
    config = train(
        args.algo,
        args.timesteps,
        args.out,
        scenario=args.scenario,
        seed=args.seed,
        copies=args.copies,
        threads=args.threads,
        overrides=parse_set(args.overrides),
        hyperparams=args.hyperparams,
        progress=not args.no_progress and on_terminal(),
        stdout_log=args.log_stdout,
        overwrite=args.overwrite,
    )
    if config["interrupted"]:
        print(
            f"interrupted at {config['timesteps']} agent-steps; saved that model to {args.out}",
            file=sys.stderr,
        )
        return 130
    print(
        f"trained {config['algo']} for {config['timesteps']} agent-steps in "
        f"{config['wall_time_s']:.0f} s ({config['agent_steps_per_s']:.0f}/s); wrote {args.out}"
    )
    report_heldout(Path(args.out), args.heldout_seeds, progress=not args.no_progress)
    return 0


if __name__ == "__main__":
    sys.exit(main())
