"""The ``uav-formation`` command line.

- ``uav-formation reproduce --seeds 5 --out results/paper``: the paper's four variants
  ({PIO, LFPIO} x {NFTSMO off, on}) on the same seeds: Table 2, Figs. 5-9, summary and report
  (:mod:`uav_formation_env.reproduce`).
- ``uav-formation evaluate --policy lfpio --observer on --seeds 5 --out results/eval``: one policy
  (``lfpio``, ``pio``, ``pso``, ``heuristic``, ``random`` or a stable-baselines3 model path) over
  seeds: per-step CSV and ``summary.json`` (:mod:`uav_formation_env.evaluation`).
- ``uav-formation run --out results/run``: one episode of the heuristic controller.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from uav_formation_env.config_io import resolve_scenario, with_overrides


def _run(args: argparse.Namespace) -> int:
    """One heuristic episode: the evaluation runner with the consensus controller."""
    from uav_formation_env.evaluation import (
        HeuristicPolicy,
        json_ready,
        run_episodes,
        write_json,
        write_records,
    )
    from uav_formation_env.plotting import plot_trajectories

    scenario = resolve_scenario(args.scenario)
    if args.observer is not None:
        scenario = with_overrides(scenario, {"observer.enabled": args.observer == "on"})
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    batch = run_episodes(
        scenario,
        HeuristicPolicy(scenario),
        [args.seed],
        policy_name="heuristic",
        progress=not args.quiet,
        desc="run (heuristic)",
    )
    write_records(batch, out / "trajectory.csv")
    plot_trajectories(
        batch.z[:, 0, :, :3], scenario, out / "trajectories.png", title="heuristic controller"
    )
    events = [
        {"obstacle": o, "event": name, "t": float(times[0, o])}
        for name, times in (("activate", batch.activation_time), ("restore", batch.restore_time))
        for o in range(times.shape[1])
        if np.isfinite(times[0, o])
    ]
    summary = {
        "scenario": scenario.name,
        "seed": args.seed,
        "realised_cost_per_uav": batch.stage_cost[:, 0].sum(axis=0).tolist(),
        "min_obstacle_surface_distance_m": float(batch.obstacle_surface[1:, 0].min()),
        "collisions": int(batch.collision[:, 0].sum()),
        "events": sorted(events, key=lambda e: e["t"]),
    }
    write_json(summary, out / "summary.json")
    print(json.dumps(json_ready(summary), indent=2))
    return 0


def _scenario_for(args: argparse.Namespace):
    scenario = resolve_scenario(args.scenario)
    overrides = {}
    if getattr(args, "observer", None) is not None:
        overrides["observer.enabled"] = args.observer == "on"
    duration = _duration(args)
    if duration is not None:
        overrides["duration"] = duration
    return with_overrides(scenario, overrides) if overrides else scenario


def _duration(args: argparse.Namespace) -> float | None:
    if args.duration is not None:
        return float(args.duration)
    if args.quick:
        from uav_formation_env.reproduce import QUICK_DURATION_S

        return QUICK_DURATION_S
    return None


def _seeds(args: argparse.Namespace) -> list[int]:
    if args.seeds < 1:
        raise SystemExit("--seeds must be >= 1")
    return list(range(args.seed_start, args.seed_start + args.seeds))


def _evaluate(args: argparse.Namespace) -> int:
    from uav_formation_env.evaluation import (
        json_ready,
        make_policy,
        run_episodes,
        summarise,
        write_json,
        write_records,
    )
    from uav_formation_env.plotting import plot_trajectories

    scenario = _scenario_for(args)
    seeds = _seeds(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    policy = make_policy(args.policy, scenario, algo=args.algo)
    batch = run_episodes(
        scenario,
        policy,
        seeds,
        policy_name=args.policy,
        progress=not args.quiet,
        desc=f"evaluate {Path(args.policy).name} x {len(seeds)} seeds",
    )
    summary = json_ready(summarise(batch))
    write_records(batch, out / "records.csv")
    write_json(summary, out / "summary.json")
    plot_trajectories(
        batch.z[:, 0, :, :3],
        scenario,
        out / "trajectories.png",
        title=f"{args.policy}, observer {'on' if scenario.observer.enabled else 'off'}, "
        f"seed {seeds[0]}",
    )
    keys = (
        "triggers_per_uav",
        "triggers_mean",
        "realised_cost_mean",
        "formation_rmse_m",
        "min_obstacle_surface_distance_m",
        "min_separation_m",
        "collisions",
        "observer_rms_error",
        "wall_time_per_step_s",
    )
    print(json.dumps({k: summary[k] for k in keys}, indent=2))
    print(f"wrote {out / 'records.csv'}, {out / 'summary.json'}, {out / 'trajectories.png'}")
    return 0


def _reproduce(args: argparse.Namespace) -> int:
    from uav_formation_env.reproduce import LABELS, reproduce

    result = reproduce(
        args.out,
        seeds=_seeds(args),
        scenario=args.scenario,
        duration=_duration(args),
        jobs=args.jobs,
        progress=not args.quiet,
        records=args.records,
        game_variants=[] if args.game_variants == ["none"] else args.game_variants,
    )
    summary = result.summary
    print(f"wall time {summary['wall_time_s']:.1f} s ({len(summary['seeds'])} seeds)")
    for variant, s in summary["variants"].items():
        per_uav = " ".join(f"{x:6.1f}" for x in s["triggers_per_uav"])
        print(
            f"{LABELS[variant]:>15}: triggers {per_uav} | mean {s['triggers_mean']:6.1f} "
            f"(paper {s['paper_triggers_mean']:g}) | min centre dist "
            f"{s['min_obstacle_center_distance_m']:.1f} m | collisions {s['collisions']}"
        )
    for row in summary["nash_gap"].values():
        print(
            f"{row['label']:>40}: Nash gap median {row['gap_median']:.3g} "
            f"p90 {row['gap_p90']:.3g} | {row['policy_ms_per_step']:.2f} ms/step"
        )
    print(f"wrote {result.out}/table2.csv, nash_gap.csv, summary.json, REPORT.md and figures")
    return 0


def _add_common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", default="paper", help="registered name or YAML path")
    parser.add_argument("--seeds", type=int, default=5, help="number of episodes (seeds)")
    parser.add_argument("--seed-start", type=int, default=0, help="first seed (then +1, ...)")
    parser.add_argument("--duration", type=float, default=None, help="episode length [s]")
    parser.add_argument(
        "--quick", action="store_true", help="20 s episodes (smoke test; --duration wins)"
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="uav-formation", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="fly a scenario with the heuristic consensus controller")
    run.add_argument("--scenario", default="paper", help="registered name or YAML path")
    run.add_argument("--seed", type=int, default=0)
    run.add_argument("--observer", choices=["on", "off"], default=None)
    run.add_argument("--out", default="results/run")
    run.add_argument("--quiet", action="store_true")
    run.set_defaults(func=_run)

    evaluate = sub.add_parser(
        "evaluate",
        help="evaluate a policy over seeds (per-step CSV, summary.json)",
        description="Run one policy on B seeds as one batch and write records.csv, "
        "summary.json and trajectories.png (first seed).",
    )
    evaluate.add_argument(
        "--policy",
        default="lfpio",
        help="lfpio, pio, pso, exact, nash (reference DMPC), heuristic, random, or a SB3 "
        "model path (.zip; a vecnormalize.pkl beside it is applied)",
    )
    evaluate.add_argument("--algo", default=None, help="SB3 algorithm of a model (default: try)")
    evaluate.add_argument("--observer", choices=["on", "off"], default=None)
    evaluate.add_argument("--out", default="results/eval")
    _add_common(evaluate)
    evaluate.set_defaults(func=_evaluate)

    reproduce = sub.add_parser(
        "reproduce",
        help="the paper's four variants: Table 2, Figs. 5-9, REPORT.md",
        description="Fly {PIO, LFPIO} x {NFTSMO off, on} on the same seeds (each variant's "
        "seeds as one batch) and write table2.csv, summary.json, the figures and REPORT.md.",
    )
    reproduce.add_argument("--out", default="results/paper")
    reproduce.add_argument(
        "--jobs",
        type=int,
        default=0,
        help="variants run in parallel processes (default 0: one per CPU, at most 4); "
        "the numbers do not depend on it",
    )
    reproduce.add_argument(
        "--records", action="store_true", help="also write records_<variant>.csv per step"
    )
    reproduce.add_argument(
        "--game-variants",
        nargs="+",
        default=["pso_nftsmo", "exact_nftsmo", "nash_nftsmo"],
        metavar="VARIANT",
        help="more solvers of the game for the Nash-gap comparison, observer on: pso_nftsmo, "
        "exact_nftsmo, nash_nftsmo, or SB3 model paths (.zip); 'none' to skip",
    )
    _add_common(reproduce)
    reproduce.set_defaults(func=_reproduce)

    # Listed here for --help only: main() hands every argument after "train" to baselines.train.
    sub.add_parser(
        "train",
        help="train PPO or SAC with one policy shared by all UAVs (the [rl] extra; "
        "`uav-formation train --help` for its options)",
        add_help=False,
    )
    return parser


def _train(argv: list[str]) -> int:
    try:
        from baselines.train import main as train_main
    except ImportError as error:
        raise SystemExit(
            "uav-formation train needs the [rl] extra (torch, stable-baselines3) and the "
            f"baselines package of this repository: {error}"
        ) from error
    return int(train_main(argv))


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["train"]:
        return _train(argv[1:])
    args = build_parser().parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
