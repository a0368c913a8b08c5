"""The ``uav-formation`` command line."""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from uav_formation_env.config_io import resolve_scenario, with_overrides
from uav_formation_env.policies.heuristic import consensus_pd
from uav_formation_env.sim import FormationSim


def _run(args: argparse.Namespace) -> int:
    scenario = resolve_scenario(args.scenario)
    if args.observer is not None:
        scenario = with_overrides(scenario, {"observer.enabled": args.observer == "on"})
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sim = FormationSim(scenario, batch_size=1)
    result = sim.reset(seed=args.seed)
    offsets = sim.offsets
    rows = []
    positions = [result.z[0, :, :3].copy()]
    total_cost = np.zeros(scenario.n_uav)
    min_obstacle = np.inf
    events = []
    for _ in tqdm(range(scenario.n_steps), desc="run (heuristic)", disable=args.quiet):
        u_n = consensus_pd(
            result.z, result.reference_velocity, result.adjacency, offsets, sim.u_max
        )
        result = sim.step(u_n)
        positions.append(result.z[0, :, :3].copy())
        total_cost += result.cost.total[0]
        min_obstacle = min(min_obstacle, float(result.obstacle_distance.min()))
        for o in np.flatnonzero(result.activated[0]):
            events.append({"obstacle": int(o), "event": "activate", "t": float(result.t[0])})
        for o in np.flatnonzero(result.restored[0]):
            events.append({"obstacle": int(o), "event": "restore", "t": float(result.t[0])})
        for i in range(scenario.n_uav):
            rows.append(
                [int(result.step[0]), float(result.t[0]), i + 1]
                + result.z[0, i].tolist()
                + result.u_applied[0, i].tolist()
                + result.disturbance[0, i].tolist()
                + result.estimate[0, i].tolist()
                + [int(result.groups[0, i]), float(result.cost.total[0, i])]
            )
    header = ["step", "t", "uav", "x", "y", "z", "vx", "vy", "vz", "ux", "uy", "uz"]
    header += ["dx", "dy", "dz", "dhat_x", "dhat_y", "dhat_z", "group", "J_stage"]
    with open(out / "trajectory.csv", "w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(header)
        writer.writerows(rows)
    from uav_formation_env.plotting import plot_trajectories

    plot_trajectories(
        np.asarray(positions), scenario, out / "trajectories.png", title="heuristic controller"
    )
    summary = {
        "scenario": scenario.name,
        "seed": args.seed,
        "realised_cost_per_uav": total_cost.tolist(),
        "min_obstacle_surface_distance_m": min_obstacle,
        "events": events,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    print(json.dumps(summary, indent=2))
    return 0


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
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
