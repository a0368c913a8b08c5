"""Train PPO or SAC with one policy shared by every UAV (parameter sharing).

    python -m uav_formation_baselines.train --algo ppo --timesteps 1000000 --out runs/ppo_paper \
        [--scenario paper] [--seed 0] [--copies 8] [--threads 1] [--set key=value ...]

Timesteps are *agent*-timesteps: SB3's ``num_timesteps``, which counts every (copy, agent) entry
of the :class:`~uav_formation_env.envs.vector.FormationVecEnv`, so one control step of B copies
of the paper's 5 UAVs is 5 B timesteps (PPO rounds up to whole rollouts of n_steps x 5 B).

The output directory holds ``model.zip`` and ``vecnormalize.pkl`` (load both with
``uav-formation evaluate --policy DIR/model.zip``), ``config.yaml`` (resolved hyper-parameters,
scenario, seed, timesteps, wall time), ``scenario.yaml`` (the evaluated scenario), ``progress.csv``
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
    from uav_formation_baselines.wrappers import make_training_env

    env, base = make_training_env(scen, training, gamma=float(algo_kwargs.get("gamma", 0.99)))
    model = cls(training["policy"], env, seed=seed, device="cpu", verbose=0, **algo_kwargs)
    model.set_logger(_logger(out, stdout_log))
    callbacks = []
    if training["eval_freq"]:
        callbacks.append(
            FormationEvalCallback(
                scen, training["eval_seeds"], training["eval_freq"], out, training["eval_duration"]
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
    save_scenario(scen, out / "scenario.yaml")
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


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="python -m uav_formation_baselines.train",
        description="Train PPO or SAC on a uav_formation_env scenario, one policy shared by "
        "all UAVs.",
    )
    parser.add_argument("--algo", choices=ALGOS, required=True)
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
    parser.add_argument("--overwrite", action="store_true", help="replace an earlier run at --out")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit code."""
    args = build_parser().parse_args(None if argv is None else list(argv))
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
    return 0


if __name__ == "__main__":
    sys.exit(main())
