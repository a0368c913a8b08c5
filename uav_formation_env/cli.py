"""The ``uav-formation`` command line.

- ``uav-formation reproduce --seeds 5 --out results/paper``: the paper's four variants
  ({PIO, LFPIO} x {NFTSMO off, on}) on the same seeds: Table 2, Figs. 5-10, summary and report
  (:mod:`uav_formation_env.reproduce`).
- ``uav-formation evaluate --policy lfpio --observer on --seeds 5 --out results/eval``: one policy
  (``lfpio``, ``pio``, ``pso``, ``exact``, ``nash``, ``heuristic``, ``random``, or a saved model:
  a run directory, an SB3 ``.zip`` or a ``.pt``) over seeds: per-step CSV and ``summary.json``
  (:mod:`uav_formation_env.evaluation`).
- ``uav-formation render --policy lfpio --seed 0 --out episode.gif``: one episode as a GIF (or
  MP4 with the ``[video]`` extra).
- ``uav-formation run --out results/run``: one episode of the heuristic controller.
- ``uav-formation train --algo ppo --timesteps 20000 --out runs/ppo``: train a policy shared by
  all UAVs into a run directory that ``evaluate --policy`` flies.

A user error (a bad argument, a missing file, an invalid scenario) prints one line,
``uav-formation: error: ...``, and exits with status 2; ``--debug`` shows the traceback.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from uav_formation_env.config_io import SCENARIOS, resolve_scenario, with_overrides
from uav_formation_env.run_folder import atomic_file, check_out, run_folder


class UserError(Exception):
    """A mistake in the command line's input, printed as one line."""


def on_terminal() -> bool:
    """Both stdout and stderr are terminals: progress bars only there, never in logs."""
    return sys.stdout.isatty() and sys.stderr.isatty()


def _progress(args: argparse.Namespace) -> bool:
    return not args.quiet and on_terminal()


def _run(args: argparse.Namespace) -> int:
    """One heuristic episode: the evaluation runner with the consensus controller."""
    from uav_formation_env.evaluation import json_ready

    scenario = resolve_scenario(args.scenario)
    if args.observer is not None:
        scenario = with_overrides(scenario, {"observer.enabled": args.observer == "on"})
    with run_folder(args.out, overwrite=args.overwrite, command="run") as out:
        summary = _run_into(args, scenario, out)
    print(json.dumps(json_ready(summary), indent=2))
    return 0


def _run_into(args: argparse.Namespace, scenario, out: Path) -> dict:
    from uav_formation_env.evaluation import (
        HeuristicPolicy,
        run_episodes,
        write_json,
        write_records,
    )
    from uav_formation_env.plotting import plot_trajectories

    batch = run_episodes(
        scenario,
        HeuristicPolicy(scenario),
        [args.seed],
        policy_name="heuristic",
        progress=_progress(args),
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
    return summary


def _model_scenario(policy: str) -> str | Path:
    """The scenario a saved model was trained for: the ``scenario.yaml`` of its run directory
    (the directory itself, or the model file's), else ``"paper"``. A model must fly the scenario
    it was trained on: its observation layout and t / duration depend on it."""
    from uav_formation_env.policies.registry import model_scenario

    found = model_scenario(policy)
    return "paper" if found is None else found


def _scenario_for(args: argparse.Namespace):
    from uav_formation_env.tasks import evaluation_scenario

    policy = getattr(args, "policy", None)
    model = _model_scenario(policy) if policy else "paper"  # "" would name the current directory
    # evaluate / render without --scenario: a model's own scenario, else the paper's
    scenario = resolve_scenario(model if args.scenario is None else args.scenario)
    if args.scenario is not None and isinstance(model, Path):
        # a saved model senses through the observation layout it was trained with, whatever
        # scene it flies (as uav_formation_baselines.results does): a local-layout student of
        # random_swarm flies random_fields, whose own layout is the full one
        scenario = replace(scenario, observation=resolve_scenario(model).observation)
    if isinstance(model, Path):  # a run's own scenario flies under the evaluation's rules
        scenario = evaluation_scenario(scenario)
    overrides = {}
    if getattr(args, "observer", None) is not None:
        overrides["observer.enabled"] = args.observer == "on"
    duration = _duration(args)
    if duration is not None:
        overrides["duration"] = duration
    return with_overrides(scenario, overrides) if overrides else scenario


def _duration(args: argparse.Namespace) -> float | None:
    if getattr(args, "duration", None) is not None:
        return float(args.duration)
    if getattr(args, "quick", False):
        from uav_formation_env.reproduce import QUICK_DURATION_S

        return QUICK_DURATION_S
    return None


def _seeds(args: argparse.Namespace) -> list[int]:
    return list(range(args.seed_start, args.seed_start + args.seeds))


def _mission_lines(summary: dict) -> list[str]:
    """The mission metrics of a summary as a few readable lines."""
    m = summary["mission"]
    lines = [
        f"mission completed: {m['completed']}/{m['episodes']} episodes "
        f"(route error max <= {m['max_route_error_threshold_m']:g} m, every obstacle on the "
        "route met, no collision after t = 0)",
        f"realised J per UAV: {summary['realised_cost_mean']:.4g} "
        f"± {summary['realised_cost_ci95']:.2g} (95% CI over seeds)",
        "by term: " + ", ".join(f"{k} {v:.3g}" for k, v in summary["realised_cost_terms"].items()),
        f"route error: RMS {m['route_error_rms_m']:.1f} ± {m['route_error_rms_m_ci95']:.1f} m, "
        f"max {m['route_error_max_m']:.1f} ± {m['route_error_max_m_ci95']:.1f} m; velocity "
        f"RMSE {m['velocity_rmse_mps']:.2f} m/s",
        f"collisions after t = 0: {m['collisions_after_start']} UAV-steps; min separation "
        f"after t = 0: {m['min_separation_after_start_m']:.1f} m",
    ]
    for name, o in m["obstacles"].items():
        required = sum(o["required_per_seed"])
        lines.append(
            f"{name}: met in {o['met']}/{m['episodes']} (on the route in {required}), "
            f"closest {o['closest_center_m']:.1f} m from its centre"
        )
    for seed, why in m["failures"].items():
        lines.append(f"seed {seed} failed: {'; '.join(why)}")
    return lines


def _reference_summary(
    name: str, scenario, policy, seeds: list[int], batch_size: int, progress: bool, options: dict
) -> dict:
    """The reference ``name`` flown on the same scenario and seeds: its missions completed and
    realised J per UAV (``summary.json``'s ``reference``)."""
    from uav_formation_env.evaluation import fly_in_chunks, summarise_digests

    digests = fly_in_chunks(
        scenario, policy, seeds, batch_size, policy_name=name, progress=progress, **options
    )
    summary = summarise_digests(digests)
    return {
        "policy": name,
        "completed": int(summary["mission"]["completed"]),
        "realised_cost_mean": float(summary["realised_cost_mean"]),
    }


def _evaluate(args: argparse.Namespace) -> int:
    from uav_formation_env.core.array_api import torch_device
    from uav_formation_env.evaluation import (
        digest,
        fly_in_chunks,
        json_ready,
        make_policy,
        summarise_digests,
        write_json,
        write_records,
    )
    from uav_formation_env.evaluation.heldout import versus_reference
    from uav_formation_env.plotting import plot_trajectories
    from uav_formation_env.policies.shield import SafetyShield
    from uav_formation_env.scenes import n_uav_range

    if args.device is not None and args.backend != "torch":
        raise ValueError(f"--device {args.device} needs --backend torch")
    scenario = _scenario_for(args)
    seeds = _seeds(args)
    desc = f"evaluate {Path(args.policy).name} x {len(seeds)} seeds"
    low, high = n_uav_range(scenario)
    reference = None  # the --compare policy
    if args.backend == "ray":
        from uav_formation_env.distributed import ray_session, run_episodes_ray

        if low != high:
            raise ValueError(
                f"--backend ray: scenario {scenario.name!r} draws N in {low}..{high}, which the "
                "Ray runner does not split by N yet; use --backend local"
            )
        if args.random_source != "generator":
            raise ValueError("--random-source counter is not available with --backend ray")
        for flag in ("shield", "compare"):
            if getattr(args, flag):
                raise ValueError(
                    f"--{flag} is not available with --backend ray; use --backend local"
                )
        make_policy(args.policy, scenario, algo=args.algo)  # bad names fail here, not in a task
        check_out(args.out, args.overwrite)  # before the episodes, which write nothing
        with ray_session(args.address):
            batches = [
                run_episodes_ray(
                    scenario,
                    args.policy,
                    seeds,
                    algo=args.algo,
                    chunk_size=args.chunk_size,
                    progress=_progress(args),
                    desc=desc + " (ray)",
                )
            ]
    else:
        options = {}
        if args.backend == "torch":
            options = {"backend": "torch", "device": torch_device(args.device)}
        policy = make_policy(
            args.policy,
            scenario,
            algo=args.algo,
            random=args.random_source,
            trust_pickle=args.trust_pickle,
        )
        if args.shield:
            policy = SafetyShield(policy, scenario)
        if args.compare:  # a bad name fails here, before any episode
            reference = make_policy(args.compare, scenario, random=args.random_source)
        batches = None
    label = args.policy + (" + shield" if args.shield else "")
    first: list = []  # the first batch's first seed, for the figure
    shielded_steps = [0, 0]  # the shield's interventions and UAV-steps over every batch
    with run_folder(args.out, overwrite=args.overwrite, command="evaluate") as out:

        def record(batch) -> None:  # per-step rows, appended chunk after chunk
            path = out / f"records_n{batch.z.shape[2]}.csv"
            write_records(batch, path, append=path.exists())
            if not first:
                first.append((batch.z[:, 0, :, :3], batch.scenes, batch.seeds[0]))
            if args.shield:
                shielded_steps[0] += policy.interventions
                shielded_steps[1] += policy.uav_steps

        if batches is None:  # local or torch: chunks of --batch-size seeds, digested as flown
            digests = fly_in_chunks(
                scenario,
                policy,
                seeds,
                args.batch_size,
                on_batch=record,
                policy_name=label,
                progress=_progress(args),
                desc=desc,
                **options,
            )
        else:
            for batch in batches:
                record(batch)
            digests = [digest(batch) for batch in batches]
        summary = json_ready(summarise_digests(digests))
        tables = sorted(out.glob("records_n*.csv"))
        names = [path.name for path in tables]
        if len(tables) == 1:  # one N: one table
            tables[0].rename(out / "records.csv")
            names = ["records.csv"]
        if args.shield:
            summary["shield"] = {
                "config": asdict(policy.config),
                "intervention_rate": shielded_steps[0] / max(shielded_steps[1], 1),
            }
        if reference is not None:
            ref = _reference_summary(
                args.compare, scenario, reference, seeds, args.batch_size, _progress(args), options
            )
            ref["cost_ratio"] = summary["realised_cost_mean"] / ref["realised_cost_mean"]
            summary["reference"] = ref
        write_json(summary, out / "summary.json")
        positions, scenes, seed = first[0]
        plot_trajectories(
            positions,
            scenario if scenes is None else scenes[0],  # the first seed's scene
            out / "trajectories.png",
            title=f"{args.policy}{' + safety shield' if args.shield else ''}, observer "
            f"{'on' if scenario.observer.enabled else 'off'}, seed {seed}",
        )
    observer = "on" if scenario.observer.enabled else "off"
    shielded = " behind the safety shield" if args.shield else ""
    print(
        f"{args.policy}{shielded} on {scenario.name!r} (observer {observer}, "
        f"{scenario.observation.kind} "
        f"observation), seeds {seeds[0]}..{seeds[-1]}, {scenario.duration:g} s episodes"
    )
    for line in _mission_lines(summary):
        print(f"  {line}")
    if "reference" in summary:
        ref = summary["reference"]
        versus = versus_reference(
            summary["realised_cost_mean"],
            ref["policy"],
            ref["realised_cost_mean"],
            ref["completed"],
            len(seeds),
        )
        print(f"  realised J per UAV against {ref['policy']} on the same seeds: {versus}")
    if summary["triggers_mean"] is not None:
        print(f"  event-triggered steps per UAV: {summary['triggers_mean']:.1f}")
    if args.shield:
        rate = summary["shield"]["intervention_rate"]
        print(f"  safety shield changed the action on {100 * rate:.2f} % of UAV-steps")
    written = [Path(args.out) / name for name in (*names, "summary.json", "trajectories.png")]
    print(f"wrote {', '.join(str(path) for path in written)}")
    return 0


def _render(args: argparse.Namespace) -> int:
    from uav_formation_env.evaluation import make_policy
    from uav_formation_env.render import render_episode

    scenario = _scenario_for(args)  # with --duration: the policy sees the episode's length
    policy = make_policy(args.policy, scenario, algo=args.algo, trust_pickle=args.trust_pickle)
    out = Path(args.out)
    if out.is_dir():
        raise UserError(f"--out {args.out!r} is a directory; expected a .gif or .mp4 file name")
    if out.suffix.lower() not in (".gif", ".mp4"):  # before the episode is flown
        raise UserError(f"--out {args.out!r} must end in .gif or .mp4")
    with atomic_file(out, overwrite=args.overwrite) as partial:
        render_episode(
            scenario,
            policy,
            args.seed,
            partial,
            policy_name=args.policy,
            fps=args.fps,
            every=args.every,
            progress=_progress(args),
        )
    print(f"wrote {out}")
    return 0


def _reproduce(args: argparse.Namespace) -> int:
    from uav_formation_env.reproduce import LABELS, reproduce

    with run_folder(args.out, overwrite=args.overwrite, command="reproduce") as out:
        result = reproduce(
            out,
            seeds=_seeds(args),
            scenario=args.scenario,
            duration=_duration(args),
            jobs=args.jobs,
            progress=_progress(args),
            records=args.records,
            game_variants=[] if args.game_variants == ["none"] else args.game_variants,
            backend=args.backend,
            address=args.address,
            chunk_size=args.chunk_size,
            device=args.device,
            random=args.random_source,
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
    for variant, s in summary["variants"].items():
        m = s["mission"]
        print(
            f"{LABELS[variant]:>15}: mission completed {m['completed']}/{m['episodes']} | route "
            f"error max {m['route_error_max_m']:.1f} m | collisions after t = 0 "
            f"{m['collisions_after_start']}"
        )
    print(f"wrote {args.out}/table2.csv, nash_gap.csv, summary.json, REPORT.md and figures")
    duration, full = _duration(args), resolve_scenario(args.scenario).duration
    if duration is not None and duration < full:
        print(
            f"warning: {duration:g} s episodes, not the scenario's {full:g} s: trigger counts, "
            "costs and events are not comparable to the paper's Table 2"
        )
    return 0


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Defaults in every option's help, and descriptions as written."""


class OneLineParser(argparse.ArgumentParser):
    """argparse with one-line errors: ``uav-formation: error: ...``, exit status 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"uav-formation: error: {message} (see {self.prog} --help)\n")


def integer_at_least(minimum: int):
    """An argparse type: an integer >= ``minimum``, else a message naming the value."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}, got {value}")
        return value

    parse.__name__ = f"integer >= {minimum}"
    return parse


def positive_number(text: str) -> float:
    """An argparse type: a finite number > 0."""

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text}")
    return value


TRUST_PICKLE_HELP = (
    "let a stable-baselines3 model read its vecnormalize.pkl: unpickling runs code from the "
    "file, so accept this risk only for files you made yourself"
)
SCENARIO_HELP = f"registered name ({', '.join(SCENARIOS)}) or path of a YAML scenario"


MODEL_SCENARIO_HELP = (
    f"{SCENARIO_HELP}; None: the scenario.yaml of a saved model's run directory, else paper "
    "(a saved model flies any scenario through its own observation layout)"
)


def _add_common(parser: argparse.ArgumentParser, model_scenario: bool = False) -> None:
    if model_scenario:
        parser.add_argument("--scenario", default=None, help=MODEL_SCENARIO_HELP)
    else:
        parser.add_argument("--scenario", default="paper", help=SCENARIO_HELP)
    parser.add_argument(
        "--seeds", type=integer_at_least(1), default=5, help="number of episodes (seeds)"
    )
    parser.add_argument(
        "--seed-start", type=integer_at_least(0), default=0, help="first seed (then +1, ...)"
    )
    parser.add_argument("--duration", type=positive_number, default=None, help="episode length [s]")
    parser.add_argument(
        "--quick", action="store_true", help="20 s episodes (smoke test; --duration wins)"
    )
    parser.add_argument(
        "--quiet", action="store_true", help="no progress bar (none where output is not a terminal)"
    )
    parser.add_argument(
        "--backend",
        choices=["local", "ray", "torch"],
        default="local",
        help="'ray': seeds (and variants) as Ray tasks, the same numbers ([ray] extra); "
        "'torch': all seeds as one batch of the torch episode layer on --device, the DMPC "
        "metaheuristics acting on it ([rl] extra)",
    )
    parser.add_argument(
        "--device",
        default=None,
        help="torch device with --backend torch, e.g. cuda or cpu (None: cuda if available)",
    )
    parser.add_argument(
        "--random-source",
        choices=["generator", "counter"],
        default="generator",
        help="the DMPC optimisers' random numbers: each episode's numpy generator (the paper "
        "reproduction's numbers), or counter-based draws made where the optimiser runs "
        "(--backend torch on a GPU)",
    )
    parser.add_argument(
        "--address",
        default=None,
        help="Ray cluster to use with --backend ray (e.g. auto or ray://HEAD:10001; "
        "None: start a local Ray instance)",
    )
    parser.add_argument(
        "--chunk-size", type=integer_at_least(1), default=1, help="seeds per Ray task"
    )


def plain_text(docstring: str) -> str:
    """A docstring as terminal text: ``:mod:`x``` -> x, ````x```` -> x."""
    return re.sub(r":\w+:`([^`]*)`", r"\1", docstring).replace("``", "")


def _version() -> str:
    from uav_formation_env import __version__

    return __version__


def _add_overwrite(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an earlier run at --out (outputs are written beside it and moved into "
        "place when the run is done; an interrupted or failed run leaves --out as it was)",
    )


def build_parser() -> argparse.ArgumentParser:
    from uav_formation_env.policies.registry import POLICY_HELP
    from uav_formation_env.reproduce.nash_analysis import NASH_FIGURE
    from uav_formation_env.reproduce.variants import FIGURES

    parser = OneLineParser(
        prog="uav-formation", description=plain_text(__doc__), formatter_class=_HelpFormatter
    )
    parser.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    run = sub.add_parser(
        "run",
        help="fly a scenario with the heuristic consensus controller",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    run.add_argument("--scenario", default="paper", help=SCENARIO_HELP)
    run.add_argument("--seed", type=integer_at_least(0), default=0, help="episode seed")
    run.add_argument("--observer", choices=["on", "off"], default=None, help="override")
    run.add_argument("--out", default="results/run", help="output directory")
    _add_overwrite(run)
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.set_defaults(func=_run)

    evaluate = sub.add_parser(
        "evaluate",
        help="evaluate a policy over seeds: mission metrics, per-step CSV, summary.json",
        description="Run one policy on seeds (in batches of --batch-size) and write records.csv, "
        "summary.json (cost and mission metrics: route error, obstacles met, collisions after "
        "t = 0, completion) and trajectories.png (first seed).",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    evaluate.add_argument("--policy", default="lfpio", help=POLICY_HELP)
    evaluate.add_argument("--algo", default=None, help="SB3 algorithm of a model (None: try each)")
    evaluate.add_argument("--trust-pickle", action="store_true", help=TRUST_PICKLE_HELP)
    evaluate.add_argument(
        "--observer", choices=["on", "off"], default=None, help="override the scenario's"
    )
    evaluate.add_argument("--out", default="results/eval", help="output directory")
    _add_overwrite(evaluate)
    evaluate.add_argument(
        "--shield",
        action="store_true",
        help="fly the policy behind the safety shield (control barrier functions that keep "
        "each UAV out of the obstacles and away from the UAVs it senses; local observation "
        "layout): the result is the policy and the shield",
    )
    evaluate.add_argument(
        "--compare",
        default=None,
        metavar="POLICY",
        help="also fly this policy (e.g. lfpio) on the same seeds and print the realised J "
        "against its (summary.json: reference)",
    )
    evaluate.add_argument(
        "--batch-size",
        type=integer_at_least(1),
        default=100,
        help="seeds flown as one batch; memory holds one batch (about 4 MB per 200 s episode "
        "of 5 UAVs), the summary and records are those of every seed",
    )
    _add_common(evaluate, model_scenario=True)
    evaluate.set_defaults(func=_evaluate)

    render = sub.add_parser(
        "render",
        help="fly one episode and write it as a GIF (or MP4 with the [video] extra)",
        description="Fly one episode of a policy and write its top view as an animation: "
        "the UAVs (numbered 1..N, as UAV1..UAVN in the figures and reports) with their trails, "
        "links and reference-velocity arrows, the obstacles with their safety circles, and "
        "the time. A .gif needs nothing more; a .mp4 needs the [video] extra.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    render.add_argument("--policy", default="lfpio", help=POLICY_HELP)
    render.add_argument("--algo", default=None, help="SB3 algorithm of a model (None: try each)")
    render.add_argument("--trust-pickle", action="store_true", help=TRUST_PICKLE_HELP)
    render.add_argument("--scenario", default=None, help=MODEL_SCENARIO_HELP)
    render.add_argument("--seed", type=integer_at_least(0), default=0, help="episode seed")
    render.add_argument("--observer", choices=["on", "off"], default=None, help="override")
    render.add_argument("--duration", type=positive_number, default=None, help="episode length [s]")
    render.add_argument(
        "--quick", action="store_true", help="20 s episode (a quick look; --duration wins)"
    )
    render.add_argument("--fps", type=integer_at_least(1), default=10, help="frames per second")
    render.add_argument(
        "--every", type=integer_at_least(1), default=5, help="one frame every K steps"
    )
    render.add_argument("--out", default="results/episode.gif", help="a .gif or .mp4 file")
    _add_overwrite(render)
    render.add_argument("--quiet", action="store_true", help="no progress bar")
    render.set_defaults(func=_render)

    figures = ", ".join((*FIGURES, NASH_FIGURE))
    reproduce = sub.add_parser(
        "reproduce",
        help="the paper's four variants: Table 2, Figs. 5-10, REPORT.md",
        description="Fly {PIO, LFPIO} x {NFTSMO off, on} on the same seeds (each variant's "
        "seeds as one batch), plus the game variants, and write table2.csv, nash_gap.csv, "
        f"summary.json (with the mission metrics), REPORT.md and the figures {figures}.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    reproduce.add_argument("--out", default="results/paper", help="output directory")
    _add_overwrite(reproduce)
    reproduce.add_argument(
        "--jobs",
        type=integer_at_least(0),
        default=0,
        help="variants run in parallel processes (0: one per CPU, at most one per variant); "
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

    # Listed here for --help only: main() hands every argument after "train" to _train.
    sub.add_parser(
        "train",
        help=f"train one policy shared by all UAVs (--algo {', '.join(TRAINERS)}) into a run "
        "directory that evaluate flies (`uav-formation train --help`)",
        add_help=False,
    )
    return parser


def _train_sb3(argv: list[str]) -> int:
    """``--algo ppo|sac``, and the help of ``uav-formation train`` (it lists every trainer)."""
    from uav_formation_baselines.train import main as train_main

    return int(train_main(argv, prog="uav-formation train", algos=tuple(TRAINERS)))


RLLIB_VENV = (
    "--algo rllib-ppo runs in a virtual environment of its own: ray[rllib] 2.60 pins gymnasium "
    "1.2.2, so installing it into this one would downgrade gymnasium here. `bash "
    "tests/rllib/run.sh` builds .venv-rllib (and runs the RLlib smoke test); then run "
    "`.venv-rllib/bin/uav-formation train --algo rllib-ppo ...` and evaluate its policy.pt in "
    "any environment with torch (docs/integrations.md)"
)


def _train_rllib(argv: list[str]) -> int:
    """``--algo rllib-ppo``: the RLlib recipe, where ray.rllib imports (its own venv)."""
    from uav_formation_baselines.rllib_ppo import main as rllib_main

    if not {"-h", "--help"} & set(argv):
        try:
            import ray.rllib  # noqa: F401 - present only in the RLlib venv
        except ImportError as error:
            raise UserError(f"{RLLIB_VENV} (here: {error})") from None
    return int(rllib_main(argv))


def _train_onpolicy(argv: list[str]) -> int:
    """``--algo ppo-fast|mappo|ippo``: the in-process trainer on the training task
    (``uav_formation_baselines.onpolicy``; ``ppo-fast`` is its parameter-sharing PPO)."""
    from uav_formation_baselines.onpolicy import main as onpolicy_main

    argv = ["ppo" if item == "ppo-fast" else item.replace("=ppo-fast", "=ppo") for item in argv]
    return int(onpolicy_main(argv, prog="uav-formation train"))


# --algo -> the trainer given every argument after "train"
TRAINERS: dict[str, Callable[[list[str]], int]] = {
    "ppo-fast": _train_onpolicy,
    "mappo": _train_onpolicy,
    "ippo": _train_onpolicy,
    "ppo": _train_sb3,
    "sac": _train_sb3,
    "rllib-ppo": _train_rllib,
}


def _algo_of(argv: list[str]) -> str | None:
    """The value of ``--algo`` in ``argv`` (``--algo X`` or ``--algo=X``), else None."""
    for k, item in enumerate(argv):
        if item == "--algo" and k + 1 < len(argv):
            return argv[k + 1]
        if item.startswith("--algo="):
            return item.partition("=")[2]
    return None


def _train(argv: list[str]) -> int:
    """``uav-formation train``: the trainer of ``--algo``; without one (or an unknown one) the
    SB3 trainer's parser, which prints the help or the one-line error listing every trainer."""
    return TRAINERS.get(_algo_of(argv) or "", _train_sb3)(argv)


def _one_line(error: BaseException) -> str:
    text = error.args[0] if isinstance(error, KeyError) and error.args else str(error)
    text = " ".join(str(text).split()) or type(error).__name__
    if isinstance(error, UserError | ValueError | TypeError | KeyError | OSError | ImportError):
        return text
    return f"{text} ({type(error).__name__}; run with --debug for the traceback)"


def main(argv: list[str] | None = None) -> int:
    """Run the command line; user errors print one line and return 2."""
    argv = sys.argv[1:] if argv is None else list(argv)
    debug = "--debug" in argv
    argv = [a for a in argv if a != "--debug"]
    try:
        if argv[:1] == ["train"]:
            return _train(argv[1:])
        args = build_parser().parse_args(argv)
        return int(args.func(args))
    except KeyboardInterrupt as interrupt:
        notes = "; ".join(getattr(interrupt, "__notes__", []))
        print(f"uav-formation: interrupted{'; ' + notes if notes else ''}", file=sys.stderr)
        return 130
    except Exception as error:  # noqa: BLE001 - the CLI never shows a traceback unless asked
        if debug:
            raise
        print(f"uav-formation: error: {_one_line(error)}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
