"""Evaluate trained runs with the package's own runner, beside the reference policies.

    python -m uav_formation_baselines.evaluate runs/ppo_paper [runs/sac_paper ...] --seeds 10 \
        --compare lfpio pio heuristic random --out results/rl_eval

Every policy flies the same seeds through :func:`uav_formation_env.evaluation.make_policy`,
:func:`~uav_formation_env.evaluation.run_episodes` and
:func:`~uav_formation_env.evaluation.summarise` (what ``uav-formation evaluate`` does). The table
puts the realised cost (mean ± 95 % CI over seeds, and its ratio to LFPIO's) beside the mission
metrics of ``summarise(batch)["mission"]``: the paper's cost J_i tracks the preset *velocity*, so
a policy can leave the route, skip the obstacles and still look cheap. Columns: missions completed
k/K, route error RMS and max of the formation centroid against the preset route, velocity-tracking
RMSE, obstacles met k/K, collisions and minimum separation after t = 0; below it, every failed seed
with its causes. ``--out`` also writes the table as markdown, CSV and JSON, the full summaries and
a bar chart (cost, completion rate, route error max per policy). This module computes no metric of
its own: every number is read from the summaries.

A run directory's ``scenario.yaml`` (written by :mod:`uav_formation_baselines.train`) is the
scenario a model is flown on unless another is given: a model must fly episodes of the duration it
was trained on, since its observation carries t / duration.
"""

from __future__ import annotations

import argparse
import csv
import shlex
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml

from uav_formation_env.config import Scenario
from uav_formation_env.config_io import resolve_scenario, with_overrides
from uav_formation_env.evaluation import (
    make_policy,
    run_episode_groups,
    summarise_groups,
    write_json,
)
from uav_formation_env.policies.policy_file import is_policy_dir
from uav_formation_env.policies.registry import POLICY_NAMES, SIMPLE_POLICIES
from uav_formation_env.tasks import evaluation_scenario

REFERENCE = "lfpio"  # the policy whose realised cost the ratio column divides by
OUTPUT_FILES = (
    "comparison.md",
    "comparison.csv",
    "comparison.json",
    "summaries.json",
    "mission.png",
)


def model_path(run: str | Path, best: bool = False) -> Path:
    """The model file of a run directory (``model.zip`` or ``best/model.zip`` of an SB3 run, or
    the policy directory of the DAgger, BenchMARL and RLlib recipes) or a model file."""
    run = Path(run)
    if run.is_file() or (run / "policy.json").is_file():  # a file, or a policy directory
        return run
    if not best and is_policy_dir(run):
        return run
    path = run / "best" / "model.zip" if best else run / "model.zip"
    if not path.is_file():
        raise ValueError(f"no model at {path}")
    return path


def run_scenario(run: str | Path) -> Scenario:
    """The scenario a run's policy is evaluated on: the one it was trained for (its
    ``scenario.yaml``, else its config's scenario name, else the paper's) under the evaluation's
    rules (:func:`uav_formation_env.tasks.evaluation_scenario`)."""
    return evaluation_scenario(_trained_for(run))


def _trained_for(run: str | Path) -> Scenario:
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
    """Summary (:func:`summarise`, mission metrics included) of one policy (a reference name or a
    model path) over ``seeds``; a scene distribution that draws N flies one batch per N
    (:func:`~uav_formation_env.evaluation.summarise_groups` joins them).

    ``duration`` overrides the scenario's before the policy is built: the DMPC and heuristic read
    the time from the observation's t / duration.
    """
    if duration is not None:
        scenario = with_overrides(scenario, {"duration": float(duration)})
    policy = make_policy(str(name), scenario, algo=algo)
    batches = run_episode_groups(
        scenario, policy, list(seeds), policy_name=str(name), progress=progress
    )
    return summarise_groups(batches)


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
    references: Sequence[str] = SIMPLE_POLICIES,
    seeds: Sequence[int] = (0, 1),
    scenario: str | Path | Scenario | None = None,
    duration: float | None = None,
    best: bool = False,
    progress: bool = False,
    verbose: bool = False,
) -> dict[str, dict[str, Any]]:
    """Summaries of trained runs and reference policies on the same seeds, keyed by label (the
    run as given, or the reference name).

    The scenario is the first run's unless given. ``verbose`` prints each policy's wall time to
    stderr as it finishes.
    """
    if scenario is not None:
        scen = resolve_scenario(scenario)
    else:
        scen = run_scenario(runs[0]) if runs else resolve_scenario("paper")
    results = {}
    jobs = [(str(run), str(model_path(run, best))) for run in runs]
    jobs += [(name, name) for name in references]
    for label, name in jobs:
        start = time.perf_counter()
        results[label] = evaluate_policy_name(name, scen, seeds, duration, None, progress)
        if verbose:
            print(
                f"{label}: {len(seeds)} seeds in {time.perf_counter() - start:.1f} s",
                file=sys.stderr,
                flush=True,
            )
    return results


def comparison_row(
    label: str, summary: dict[str, Any], reference_cost: float | None = None
) -> dict[str, Any]:
    """One policy's row of the comparison: the cost beside the mission metrics, every value read
    from its :func:`summarise` summary (the ratio divides by ``reference_cost`` when given)."""
    mission = summary["mission"]
    cost = summary["realised_cost_mean"]
    row: dict[str, Any] = {
        "policy": label,
        "episodes": mission["episodes"],
        "realised_cost_mean": cost,
        "realised_cost_ci95": summary["realised_cost_ci95"],
        "cost_ratio_to_reference": cost / reference_cost if reference_cost else None,
        "completed": mission["completed"],
        "completion_rate": mission["completion_rate"],
    }
    for key in ("route_error_rms_m", "route_error_max_m", "velocity_rmse_mps"):
        row[key] = mission[key]
        row[f"{key}_ci95"] = mission[f"{key}_ci95"]
    for name, obstacle in mission["obstacles"].items():
        row[f"{name}_met"] = obstacle["met"]
        row[f"{name}_required"] = sum(obstacle["required_per_seed"])
        row[f"{name}_closest_center_m"] = obstacle["closest_center_m"]
    row["collisions_after_start"] = mission["collisions_after_start"]
    row["min_separation_after_start_m"] = mission["min_separation_after_start_m"]
    row["policy_ms_per_step"] = 1e3 * summary["policy_time_per_step_s"]
    row["failed_seeds"] = " ".join(sorted(mission["failures"], key=int))
    row["return_mean"] = summary.get("return_mean")
    row["reward"] = summary.get("reward")
    return row


def comparison_rows(
    results: dict[str, dict[str, Any]], reference: str | None = REFERENCE
) -> list[dict[str, Any]]:
    """:func:`comparison_row` of every policy; the ratio is to ``reference``'s cost if it was
    evaluated (else None)."""
    ref = results.get(reference) if reference else None
    ref_cost = ref["realised_cost_mean"] if ref else None
    return [comparison_row(label, summary, ref_cost) for label, summary in results.items()]


def _short(x: float) -> str:
    """``x`` in scientific notation with 3 significant digits, exponent without '+' and leading
    zeros (6.72e5)."""
    mantissa, exponent = f"{x:.2e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def _fixed(x: float, digits: int) -> str:
    """``x`` with ``digits`` decimals below 100, whole numbers below 10^5, else :func:`_short`."""
    if abs(x) < 100:
        return f"{x:.{digits}f}"
    return f"{x:.0f}" if abs(x) < 1e5 else _short(x)


def _pm(row: dict[str, Any], key: str, digits: int = 1) -> str:
    return f"{_fixed(row[key], digits)} ± {_fixed(row[f'{key}_ci95'], digits)}"


def _ratio(x: float | None) -> str:
    if x is None:
        return "-"
    return f"{x:.2f}x" if x < 100 else f"{x:,.0f}x"


def _met(row: dict[str, Any], obstacle: str) -> str:
    """k/K seeds where the obstacle was met, and on how many seeds the route passes it if not
    all."""
    text = f"{row[f'{obstacle}_met']}/{row['episodes']}"
    required = row[f"{obstacle}_required"]
    return text if required == row["episodes"] else f"{text} (on route in {required})"


def table_columns(
    rows: list[dict[str, Any]], reference: str | None = REFERENCE
) -> list[tuple[str, Any]]:
    """(header, cell of a row) of the comparison table; one "met" column per obstacle."""
    obstacles = [k[: -len("_met")] for k in (rows[0] if rows else {}) if k.endswith("_met")]
    columns: list[tuple[str, Any]] = [
        ("policy", lambda r: r["policy"]),
        (
            "realised J per UAV (mean ± 95% CI)",
            lambda r: f"{_short(r['realised_cost_mean'])} ± {_short(r['realised_cost_ci95'])}",
        ),
        (
            f"vs {reference.upper() if reference else 'reference'}",
            lambda r: _ratio(r["cost_ratio_to_reference"]),
        ),
        ("mission completed", lambda r: f"{r['completed']}/{r['episodes']}"),
        ("route error RMS [m]", lambda r: _pm(r, "route_error_rms_m")),
        ("route error max [m]", lambda r: _pm(r, "route_error_max_m")),
        ("velocity RMSE [m/s]", lambda r: _pm(r, "velocity_rmse_mps", 2)),
    ]
    for name in obstacles:
        columns.append((f"{name} met", lambda r, n=name: _met(r, n)))
    columns += [
        ("collisions after t = 0 (UAV-steps)", lambda r: str(r["collisions_after_start"])),
        ("min separation after t = 0 [m]", lambda r: f"{r['min_separation_after_start_m']:.2f}"),
        ("policy ms per step", lambda r: f"{r['policy_ms_per_step']:.2f}"),  # all seeds batched
    ]
    return columns


def format_table(results: dict[str, dict[str, Any]], reference: str | None = REFERENCE) -> str:
    """A plain-text table of the cost and mission columns (:func:`table_columns`) per policy."""
    rows = comparison_rows(results, reference)
    columns = table_columns(rows, reference)
    cells = [[header for header, _ in columns]]
    cells += [[cell(row) for _, cell in columns] for row in rows]
    widths = [max(len(line[c]) for line in cells) for c in range(len(columns))]
    lines = [
        "  ".join(
            text.ljust(w) if c == 0 else text.rjust(w)
            for c, (text, w) in enumerate(zip(line, widths))
        )
        for line in cells
    ]
    return "\n".join(lines)


def format_markdown(results: dict[str, dict[str, Any]], reference: str | None = REFERENCE) -> str:
    """The comparison table (:func:`table_columns`) as a markdown table."""
    rows = comparison_rows(results, reference)
    columns = table_columns(rows, reference)
    lines = [
        "| " + " | ".join(header for header, _ in columns) + " |",
        "|" + "---|" * len(columns),
    ]
    lines += ["| " + " | ".join(cell(row) for _, cell in columns) + " |" for row in rows]
    return "\n".join(lines)


def format_failures(results: dict[str, dict[str, Any]], markdown: bool = False) -> str:
    """Per policy, every seed that did not complete the mission and why (``summarise``'s
    ``mission.failures``)."""
    lines = []
    for label, summary in results.items():
        mission = summary["mission"]
        failures = mission["failures"]
        name = f"**{label}**" if markdown else label
        lines.append(
            f"- {name}: {len(failures)}/{mission['episodes']} seeds failed"
            + ("" if failures else " (none)")
        )
        for seed in sorted(failures, key=int):
            lines.append(f"  - seed {seed}: {'; '.join(failures[seed])}")
    return "\n".join(lines)


def _csv_cell(value: Any) -> Any:
    if value is None:
        return ""
    return f"{value:.6g}" if isinstance(value, float) else value


def write_outputs(
    results: dict[str, dict[str, Any]],
    out: str | Path,
    reference: str | None = REFERENCE,
    command: str | None = None,
) -> list[Path]:
    """Write the comparison into ``out``: ``comparison.md`` (table and failed seeds),
    ``comparison.csv`` (one row per policy, :func:`comparison_row`), ``comparison.json`` (the
    rows, failures and the command), ``summaries.json`` (every :func:`summarise` summary) and
    ``mission.png`` (:func:`~uav_formation_baselines.plots.mission_bars`).

    Returns:
        the paths written, in :data:`OUTPUT_FILES` order.
    """
    from uav_formation_baselines.plots import mission_bars

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = comparison_rows(results, reference)
    first = next(iter(results.values()), {})
    seeds = first.get("seeds", [])
    thresholds = {s["mission"]["max_route_error_threshold_m"] for s in results.values()}
    threshold = thresholds.pop() if len(thresholds) == 1 else None
    limit = "each scenario's threshold" if threshold is None else f"{threshold:g} m"
    header = [
        f"Scenario {first.get('scenario')!r}, {first.get('duration_s', 0):g} s episodes, "
        f"seeds {seeds[0] if seeds else '-'}..{seeds[-1] if seeds else '-'} "
        f"({len(seeds)} episodes per policy), observer {'on' if first.get('observer') else 'off'}."
        " A mission is completed when every obstacle on the preset route is met, no UAVs "
        f"collide after t = 0 and the route error max stays <= {limit}. Realised J and "
        "the mission metrics are means over seeds ± the half-width of their 95 % confidence "
        "interval; policy ms per step is one batched call for all seeds.",
    ]
    if command:
        header = [f"```bash\n{command}\n```", ""] + header
    markdown = "\n".join(
        header
        + ["", format_markdown(results, reference), "", "Failed seeds:", ""]
        + [format_failures(results, markdown=True), ""]
    )
    paths = [out / name for name in OUTPUT_FILES]
    paths[0].write_text(markdown, encoding="utf-8")
    fields: list[str] = []
    for row in rows:
        fields += [key for key in row if key not in fields]
    with open(paths[1], "w", newline="", encoding="utf-8") as stream:
        writer = csv.DictWriter(stream, fieldnames=fields)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _csv_cell(v) for k, v in row.items()})
    failures = {label: s["mission"]["failures"] for label, s in results.items()}
    comparison = {
        "command": command,
        "scenario": first.get("scenario"),
        "duration_s": first.get("duration_s"),
        "seeds": seeds,
        "reference": reference,
        "max_route_error_threshold_m": threshold,
        "rows": rows,
        "failures": failures,
    }
    write_json(comparison, paths[2])
    write_json(results, paths[3])
    mission_bars(rows, paths[4], threshold=threshold, reference=reference)
    return paths


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit code."""
    parser = argparse.ArgumentParser(
        prog="python -m uav_formation_baselines.evaluate",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("runs", nargs="*", help="run directories or model .zip files")
    parser.add_argument("--seeds", type=int, default=2, help="episodes, seeds 0..K-1")
    parser.add_argument("--seed-start", type=int, default=0)
    parser.add_argument("--scenario", default=None, help="default: the first run's")
    parser.add_argument("--duration", type=float, default=None, help="episode length [s]")
    parser.add_argument("--best", action="store_true", help="evaluate best/model.zip")
    parser.add_argument(
        "--compare",
        nargs="*",
        default=list(SIMPLE_POLICIES),
        help=f"reference policies: any of {', '.join(POLICY_NAMES)}",
    )
    parser.add_argument(
        "--reference", default=REFERENCE, help="policy of the cost-ratio column (default lfpio)"
    )
    parser.add_argument(
        "--out",
        default=None,
        help="write comparison.{md,csv,json}, summaries.json and mission.png here",
    )
    parser.add_argument("--progress", action="store_true", help="progress bar per policy")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error("--seeds must be >= 1")
    seeds = list(range(args.seed_start, args.seed_start + args.seeds))
    argv = sys.argv[1:] if argv is None else list(argv)
    command = shlex.join(["python", "-m", "uav_formation_baselines.evaluate", *argv])
    results = compare(
        args.runs,
        args.compare,
        seeds,
        args.scenario,
        args.duration,
        best=args.best,
        progress=args.progress,
        verbose=True,
    )
    print(format_table(results, args.reference))
    print("\nfailed seeds:")
    print(format_failures(results))
    if args.out:
        paths = write_outputs(results, args.out, args.reference, command)
        print(f"wrote {', '.join(str(p) for p in paths)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
