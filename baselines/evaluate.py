"""Evaluate trained runs with the package's own runner, beside the reference policies.

    python -m uav_formation_baselines.evaluate runs/ppo_paper [runs/sac_paper ...] --seeds 5 \
        --compare heuristic random --out results/rl_eval

Every policy flies the same seeds through :func:`uav_formation_env.evaluation.make_policy`,
:func:`~uav_formation_env.evaluation.run_episodes` and
:func:`~uav_formation_env.evaluation.summarise` (what ``uav-formation evaluate`` does), so a trained
model and the DMPC / heuristic controllers are compared on one number: the realised cost.

A run directory's ``scenario.yaml`` (written by :mod:`uav_formation_baselines.train`) is the
scenario a model is flown on unless another is given: a model must fly episodes of the duration it
was trained on, since its observation carries t / duration.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml

from uav_formation_env.config import Scenario
from uav_formation_env.config_io import resolve_scenario
from uav_formation_env.evaluation import make_policy, run_episodes, summarise, write_json

TABLE_KEYS = {
    "realised_cost_mean": "cost/UAV",
    "formation_rmse_m": "rmse [m]",
    "collisions": "collisions",
    "min_separation_m": "min sep [m]",
    "min_obstacle_surface_distance_m": "min obst [m]",
    "wall_time_per_step_s": "s/step",
}


def model_path(run: str | Path, best: bool = False) -> Path:
    """The model file of a run directory (``model.zip`` or ``best/model.zip``) or a .zip path."""
    run = Path(run)
    if run.is_file():
        return run
    path = run / "best" / "model.zip" if best else run / "model.zip"
    if not path.is_file():
        raise ValueError(f"no model at {path}")
    return path


def run_scenario(run: str | Path) -> Scenario:
    """The scenario a run was trained for: its ``scenario.yaml``, else its config's scenario
    name, else the paper's."""
    run = Path(run)
    directory = run.parent if run.is_file() else run
    # a run's best/ and checkpoints/<steps>/ sit one and two levels below its directory
    for candidate in (directory, directory.parent, directory.parent.parent):
        if (candidate / "scenario.yaml").is_file():
            return resolve_scenario(candidate / "scenario.yaml")
        if (candidate / "config.yaml").is_file():
            with open(candidate / "config.yaml", encoding="utf-8") as stream:
                return resolve_scenario((yaml.safe_load(stream) or {}).get("scenario", "paper"))
    return resolve_scenario("paper")


def evaluate_policy_name(
    name: str,
    scenario: Scenario,
    seeds: Sequence[int],
    duration: float | None = None,
    algo: str | None = None,
    progress: bool = False,
) -> dict[str, Any]:
    """Summary of one policy (a reference name or a model path) over ``seeds``."""
    policy = make_policy(str(name), scenario, algo=algo)
    batch = run_episodes(
        scenario, policy, list(seeds), duration=duration, policy_name=str(name), progress=progress
    )
    return summarise(batch)


def evaluate_run(
    run: str | Path,
    seeds: Sequence[int] = (0, 1),
    scenario: str | Path | Scenario | None = None,
    duration: float | None = None,
    best: bool = False,
    progress: bool = False,
) -> dict[str, Any]:
    """Summary (:func:`summarise`) of a trained run's deterministic policy over ``seeds``.

    Args:
        run: run directory or model ``.zip`` (its ``vecnormalize.pkl`` beside it is applied).
        seeds: one episode per seed.
        scenario: None: the run's own (see :func:`run_scenario`).
        duration: episode length [s] (None: the scenario's).
        best: the best evaluated model (``best/model.zip``) instead of the final one.
        progress: progress bar over the steps.
    """
    scen = run_scenario(run) if scenario is None else resolve_scenario(scenario)
    return evaluate_policy_name(str(model_path(run, best)), scen, seeds, duration, None, progress)


def compare(
    runs: Sequence[str | Path],
    references: Sequence[str] = ("heuristic", "random"),
    seeds: Sequence[int] = (0, 1),
    scenario: str | Path | Scenario | None = None,
    duration: float | None = None,
    best: bool = False,
) -> dict[str, dict[str, Any]]:
    """Summaries of trained runs and reference policies on the same seeds, keyed by label.

    The scenario is the first run's unless given.
    """
    if scenario is not None:
        scen = resolve_scenario(scenario)
    else:
        scen = run_scenario(runs[0]) if runs else resolve_scenario("paper")
    results = {}
    for run in runs:
        results[str(run)] = evaluate_run(run, seeds, scen, duration, best)
    for name in references:
        results[name] = evaluate_policy_name(name, scen, seeds, duration)
    return results


def format_table(results: dict[str, dict[str, Any]]) -> str:
    """A plain-text table of :data:`TABLE_KEYS` per policy."""
    width = max(len(label) for label in results) if results else 10
    lines = [f"{'policy':<{width}} " + " ".join(f"{k:>12}" for k in TABLE_KEYS.values())]
    for label, summary in results.items():
        cells = []
        for key in TABLE_KEYS:
            value = summary.get(key)
            cells.append(f"{'-' if value is None else f'{value:.4g}':>12}")
        lines.append(f"{label:<{width}} " + " ".join(cells))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit code."""
    parser = argparse.ArgumentParser(
        prog="python -m uav_formation_baselines.evaluate", description=__doc__
    )
    parser.add_argument("runs", nargs="*", help="run directories or model .zip files")
    parser.add_argument("--seeds", type=int, default=2, help="episodes, seeds 0..K-1")
    parser.add_argument("--seed-start", type=int, default=0)
    parser.add_argument("--scenario", default=None, help="default: the first run's")
    parser.add_argument("--duration", type=float, default=None, help="episode length [s]")
    parser.add_argument("--best", action="store_true", help="evaluate best/model.zip")
    parser.add_argument(
        "--compare", nargs="*", default=["heuristic", "random"], help="reference policies"
    )
    parser.add_argument("--out", default=None, help="write summaries.json here")
    args = parser.parse_args(argv)
    seeds = list(range(args.seed_start, args.seed_start + args.seeds))
    results = compare(args.runs, args.compare, seeds, args.scenario, args.duration, best=args.best)
    print(format_table(results))
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        write_json(results, out / "summaries.json")
        print(f"wrote {out / 'summaries.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
