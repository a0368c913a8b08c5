"""The results table of the learned baselines: one row per algorithm over its training seeds.

    python -m uav_formation_baselines.results runs/dagger_paper_s0 runs/dagger_paper_s1 ... \
        --seeds 20 --compare lfpio pio exact nash --out results/paper_learned

Every run directory (DAgger, BenchMARL, SB3 or RLlib recipe) is flown deterministically on the
same held-out seeds of one scenario (``--scenario``, else the first run's), each model through the
observation layout of its own ``scenario.yaml`` (the training options there, reward transforms
and corridors, are not applied: evaluation flies the scenario as it is), by the project's runner
(:func:`uav_formation_baselines.evaluate.evaluate_policy_name`, as ``uav-formation evaluate``),
and its runs are grouped by the algorithm
named in their ``config.yaml`` (``algorithm:`` or SB3's ``algo:``). An algorithm's row holds,
over its training seeds, the mean and 95 % confidence half-width (Student t, one value per
training seed: that run's mean over the evaluation seeds) of the realised J per UAV, route error
max, route error RMS and velocity RMSE; the missions completed (all runs' episodes together, and
per run); collisions after t = 0 (UAV-steps, summed); wall time and agent-steps per run. A
reference policy (``--compare``) is one deterministic row whose interval is over the evaluation
seeds. Nothing is computed here that the runner's summaries do not hold.

``--out`` receives ``results.md``, ``results.csv``, ``results.json`` (rows, per-run rows and the
command), ``summaries.json`` (every summary) and ``learning_curves.png``
(:func:`uav_formation_baselines.plots.training_curves`).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import shlex
import sys
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from uav_formation_baselines.evaluate import (
    REFERENCE,
    comparison_row,
    evaluate_policy_name,
    model_path,
    run_scenario,
)
from uav_formation_baselines.onpolicy_config import ONPOLICY_ALGOS, load_config
from uav_formation_env.cli import OneLineParser
from uav_formation_env.config_io import resolve_scenario, with_overrides
from uav_formation_env.evaluation import mean_ci95, wilson_ci95, write_json
from uav_formation_env.tasks import evaluation_scenario, training_scenario

__all__ = ["algorithm_rows", "run_record", "main"]

# settings that do not change what a run learns (the evaluations move a curriculum up: they do)
_NOT_LEARNING = ("threads",)
MEASURES = ("realised_cost_mean", "route_error_max_m", "route_error_rms_m", "velocity_rmse_mps")


def run_record(run: str | Path) -> dict[str, Any]:
    """The run's ``config.yaml`` with ``algorithm``, ``agent_steps`` and ``wall_time_s`` filled
    in from whichever recipe wrote it."""
    with open(Path(run) / "config.yaml", encoding="utf-8") as stream:
        config = yaml.safe_load(stream) or {}
    algorithm = config.get("algorithm") or config.get("algo")
    if not algorithm:
        raise ValueError(f"{run}/config.yaml names no algorithm ('algorithm:' or 'algo:')")
    steps = config.get("agent_steps", config.get("timesteps", config.get("frames")))
    return {**config, "algorithm": str(algorithm), "agent_steps": steps}


def configuration_label(record: dict[str, Any]) -> str:
    """The row a run belongs to: its algorithm, then the in-process trainer's hyper-parameters
    that differ from the shipped ones, the scenario overrides it trained with (``hyperparams.env``,
    as dotted keys) and the model it started from (``init``), so that runs differing only in
    their seed share a row; a run's best validation policy (``RUN/best``, with ``selected_by``)
    is a row of its own."""
    label = record["algorithm"]
    hyperparams = record.get("hyperparams") or {}
    settings = _changed_hyperparams(label, hyperparams)
    settings += [f"{key}={value}" for key, value in _dotted(hyperparams.get("env") or {})]
    if settings:
        label += f" ({', '.join(settings)})"
    if record.get("init"):
        label += f" from {Path(str(record['init'])).name}"
    if record.get("selected_by"):
        label += ", best validation"
    return label


def _changed_hyperparams(algorithm: str, hyperparams: dict[str, Any]) -> list[str]:
    """``key=value`` of each setting of an in-process run that differs from the shipped
    ``baselines/hyperparams/onpolicy.yml``, but the torch threads (``env`` is labelled apart)."""
    if algorithm not in ONPOLICY_ALGOS:
        return []
    shipped = load_config(algorithm).as_dict()
    return [
        f"{key}={value}"
        for key, value in hyperparams.items()
        if key in shipped and key not in (*_NOT_LEARNING, "env") and value != shipped[key]
    ]


def _dotted(mapping: dict[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    items: list[tuple[str, Any]] = []
    for key, value in mapping.items():
        if isinstance(value, dict):
            items += _dotted(value, f"{prefix}{key}.")
        else:
            items.append((f"{prefix}{key}", value))
    return items


def _row(
    label: str,
    per_run: list[dict[str, Any]],
    records: list[dict[str, Any]] | None,
    reference_cost: float | None,
) -> dict[str, Any]:
    """One table row from :func:`comparison_row` rows: over training runs (``records`` given:
    mean and 95 % half-width over the runs, counts summed) or of one reference policy
    (``records`` None) or one run (an ensemble, say): its own interval over the evaluation
    seeds, as an interval over one run would be 0."""
    row: dict[str, Any] = {
        "policy": label,
        "training_seeds": None if records is None else len(per_run),
    }
    for key in MEASURES:
        if records is None or len(per_run) == 1:
            ci_key = "realised_cost_ci95" if key == "realised_cost_mean" else f"{key}_ci95"
            row[key], row[f"{key}_ci95"] = per_run[0][key], per_run[0][ci_key]
        else:
            row[key], row[f"{key}_ci95"] = mean_ci95(np.array([r[key] for r in per_run]))
    mean_cost = row["realised_cost_mean"]
    row["cost_ratio_to_reference"] = mean_cost / reference_cost if reference_cost else None
    row["completed"] = sum(r["completed"] for r in per_run)
    row["episodes"] = sum(r["episodes"] for r in per_run)
    row["completed_ci95"] = wilson_ci95(row["completed"], row["episodes"])
    row["returns_per_run"] = [r["return_mean"] for r in per_run]
    row["completed_per_run"] = [r["completed"] for r in per_run]
    row["collisions_after_start"] = sum(r["collisions_after_start"] for r in per_run)
    row["min_separation_after_start_m"] = min(r["min_separation_after_start_m"] for r in per_run)
    obstacles = [k[:-4] for k in per_run[0] if k.endswith("_met")]
    row["obstacles_met"] = {o: sum(r[f"{o}_met"] for r in per_run) for o in obstacles}
    for key, source in (
        ("wall_time_s_per_run", "wall_time_s"),
        ("agent_steps_per_run", "agent_steps"),
    ):
        values = [rec.get(source) or np.nan for rec in records] if records else None
        row[key] = None if values is None else float(np.mean(values))
    return row


def algorithm_rows(
    runs: dict[str, list[tuple[dict[str, Any], dict[str, Any]]]],
    references: dict[str, dict[str, Any]],
) -> list[dict[str, Any]]:
    """Rows of the table: per algorithm its runs' ``(record, summary)`` aggregated over training
    seeds, then one row per reference summary."""
    ref = references.get(REFERENCE)
    ref_cost = ref["realised_cost_mean"] if ref else None
    rows = []
    for algorithm, pairs in runs.items():
        per_run = [comparison_row(algorithm, summary, ref_cost) for _, summary in pairs]
        rows.append(_row(algorithm, per_run, [record for record, _ in pairs], ref_cost))
    for name, summary in references.items():
        rows.append(_row(name, [comparison_row(name, summary, ref_cost)], None, ref_cost))
    scores(rows, references)
    return rows


def scores(rows: list[dict[str, Any]], references: dict[str, dict[str, Any]]) -> None:
    """Adds each row's normalised score, ``(R - R_random) / (R_lfpio - R_random)`` with R the
    return per UAV under the training reward (mean and 95 % half-width over training runs),
    where the references hold ``random`` and LFPIO flown under that reward; else None."""
    low, high = references.get("random"), references.get(REFERENCE)
    usable = low and high and low.get("reward") == high.get("reward") == "train"
    for row in rows:
        if not usable or low["return_mean"] == high["return_mean"]:
            row["score"] = row["score_ci95"] = None
            continue
        span = high["return_mean"] - low["return_mean"]
        values = (np.array(row["returns_per_run"]) - low["return_mean"]) / span
        row["score"], row["score_ci95"] = mean_ci95(values)


def _ratio(x: float) -> str:
    """A cost ratio: two decimals near 1, three significant digits far from it (8.98e5x)."""
    return f"{x:.2f}x" if x < 100 else f"{x:.3g}x".replace("e+0", "e").replace("e+", "e")


def _pm(row: dict[str, Any], key: str, digits: int) -> str:
    return f"{row[key]:.{digits}f} ± {row[f'{key}_ci95']:.{digits}f}"


def format_markdown(rows: list[dict[str, Any]]) -> str:
    """The table as markdown."""
    head = (
        "| policy | training seeds | realised J per UAV | vs LFPIO | score | missions completed "
        "(per run) [95 % CI] | route error max [m] | route error RMS [m] | velocity RMSE [m/s] | "
        "obstacles met | collisions after t = 0 | min separation [m] | wall time per run [s] | "
        "agent-steps per run |"
    )
    lines = [head, "|" + "---|" * 14]
    for row in rows:
        cost = f"{row['realised_cost_mean']:.3g} ± {row['realised_cost_mean_ci95']:.2g}"
        ratio = row["cost_ratio_to_reference"]
        per_run = ", ".join(str(c) for c in row["completed_per_run"])
        met = ", ".join(f"{o} {k}" for o, k in row["obstacles_met"].items())
        wall = row["wall_time_s_per_run"]
        steps = row["agent_steps_per_run"]
        low, high = row["completed_ci95"]
        score = "-" if row.get("score") is None else f"{row['score']:.2f} ± {row['score_ci95']:.2f}"
        lines.append(
            f"| {row['policy']} | {row['training_seeds'] or '-'} | {cost} | "
            f"{'-' if ratio is None else _ratio(ratio)} | {score} | "
            f"{row['completed']}/{row['episodes']} ({per_run}) [{100 * low:.0f}-{100 * high:.0f} %]"
            f" | {_pm(row, 'route_error_max_m', 1)} | {_pm(row, 'route_error_rms_m', 1)}"
            f" | {_pm(row, 'velocity_rmse_mps', 2)} | {met} | {row['collisions_after_start']} | "
            f"{row['min_separation_after_start_m']:.2f} | "
            f"{'-' if wall is None else f'{wall:.0f}'} | "
            f"{'-' if steps is None else f'{steps:.3g}'} |"
        )
    return "\n".join(lines)


def _header(path: Path) -> list[str]:
    """The column names of a CSV file ([] if absent)."""
    if not path.is_file():
        return []
    with open(path, encoding="utf-8") as stream:
        return stream.readline().strip().split(",")


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(
        prog="python -m uav_formation_baselines.results",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("runs", nargs="+", help="run directories (config.yaml + model)")
    parser.add_argument("--seeds", type=int, default=20, help="episodes, seeds seed-start..")
    parser.add_argument("--seed-start", type=int, default=0)
    parser.add_argument("--scenario", default=None, help="default: the first run's")
    parser.add_argument(
        "--task",
        default=None,
        help="a task of the ladder (hold, track, paper, ...): fly it as every evaluation does, "
        "under the training reward (uav_formation_env.tasks.evaluation_scenario), so that the "
        "rows get the normalised score (with --compare lfpio random)",
    )
    parser.add_argument(
        "--observation",
        choices=("full", "local"),
        default=None,
        help="override the scenario's observation layout (a local-layout model on random_fields)",
    )
    parser.add_argument("--compare", nargs="*", default=[REFERENCE], help="reference policies")
    parser.add_argument("--out", default=None, help="output directory")
    args = parser.parse_args(argv)
    missing = [run for run in args.runs if not (Path(run) / "config.yaml").is_file()]
    if missing:
        parser.error(f"not a run directory (no config.yaml): {missing[0]}")
    if args.task is not None:
        scenario = evaluation_scenario(training_scenario(args.task))
    elif args.scenario:
        scenario = resolve_scenario(args.scenario)
    else:
        scenario = run_scenario(args.runs[0])
    if args.observation is not None:
        scenario = with_overrides(scenario, {"observation.kind": args.observation})
    seeds = list(range(args.seed_start, args.seed_start + args.seeds))
    grouped: dict[str, list[tuple[dict[str, Any], dict[str, Any]]]] = {}
    summaries: dict[str, dict[str, Any]] = {}
    for run in args.runs:
        record = run_record(run)
        # the evaluation's scenario, read through the observation layout the model was trained on
        flown = dataclasses.replace(scenario, observation=run_scenario(run).observation)
        if args.observation is not None:
            flown = scenario
        summary = evaluate_policy_name(str(model_path(run)), flown, seeds)
        grouped.setdefault(configuration_label(record), []).append((record, summary))
        summaries[str(run)] = summary
        print(f"{run}: {summary['mission']['completed']}/{len(seeds)} completed", file=sys.stderr)
    references = {name: evaluate_policy_name(name, scenario, seeds) for name in args.compare}
    summaries.update(references)
    rows = algorithm_rows(grouped, references)
    table = format_markdown(rows)
    print(table)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        argv = sys.argv[1:] if argv is None else list(argv)
        command = shlex.join(["python", "-m", "uav_formation_baselines.results", *argv])
        (out / "results.md").write_text(f"```bash\n{command}\n```\n\n{table}\n", encoding="utf-8")
        flat = [{k: v for k, v in row.items() if not isinstance(v, dict | list)} for row in rows]
        with open(out / "results.csv", "w", newline="", encoding="utf-8") as stream:
            writer = csv.DictWriter(stream, fieldnames=list(flat[0]))
            writer.writeheader()
            writer.writerows(flat)
        write_json(
            {"command": command, "scenario": scenario.name, "seeds": seeds, "rows": rows},
            out / "results.json",
        )
        write_json(summaries, out / "summaries.json")
        from uav_formation_baselines.plots import ladder_curves, training_curves

        lfpio = references.get(REFERENCE, {}).get("realised_cost_mean")
        in_process = [r for r in args.runs if "eval_return" in _header(Path(r) / "progress.csv")]
        if in_process:  # the in-process trainer: returns under the training reward
            returns = {name: s["return_mean"] for name, s in references.items()}
            ladder_curves(in_process, out / "learning_curves.png", returns, configuration_label)
        else:
            training_curves(args.runs, out / "learning_curves.png", reference_cost=lfpio)
        print(
            f"wrote {out}/results.md, results.csv, results.json, summaries.json, "
            "learning_curves.png"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
