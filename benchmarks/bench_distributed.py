"""Scaling of the Ray backend on this machine: evaluation with 1 and 2 Ray CPUs beside the local
backend in the same run, and the driver's cost per episode (prints figures, asserts nothing).

    pip install -e ".[ray]" && python benchmarks/bench_distributed.py [--seeds 8] [--duration 60]
"""

from __future__ import annotations

import argparse
import pickle
import time

from uav_formation_env.config_io import resolve_scenario, with_overrides
from uav_formation_env.distributed import ray_session, run_episodes_ray
from uav_formation_env.evaluation import (
    concatenate_batches,
    make_policy,
    run_episodes,
    summarise,
)


def timed(function, *args, **kwargs) -> float:
    start = time.perf_counter()
    function(*args, **kwargs)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--policy", default="lfpio")
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--duration", type=float, default=60.0)
    args = parser.parse_args()
    scenario = with_overrides(resolve_scenario("paper"), {"duration": args.duration})
    seeds = list(range(args.seeds))
    local = timed(run_episodes, scenario, make_policy(args.policy, scenario), seeds)
    print(f"{args.policy}, {args.seeds} seeds of {args.duration:g} s")
    print(f"local backend, one process, one batch: {local:.1f} s")
    rows = {}
    for cpus in (1, 2):
        with ray_session(num_cpus=cpus):
            run_episodes_ray(scenario, "heuristic", [0], progress=False)  # start the workers
            for chunk in (1, 4):
                rows[cpus, chunk] = timed(
                    run_episodes_ray, scenario, args.policy, seeds, chunk_size=chunk,
                    progress=False,
                )  # fmt: skip
    for chunk in (1, 4):
        one, two = rows[1, chunk], rows[2, chunk]
        print(f"ray chunk {chunk}: 1 CPU {one:.1f} s, 2 CPUs {two:.1f} s ({one / two:.2f}x)")

    full = resolve_scenario("paper")
    for name in (args.policy, "heuristic"):
        episode = timed(run_episodes, full, make_policy(name, full), [0])
        print(f"one 200 s episode of {name}: {episode:.2f} s")
    batch = run_episodes(full, make_policy("heuristic", full), [0])
    blob = pickle.dumps(batch)
    start = time.perf_counter()
    parts = [pickle.loads(blob) for _ in range(64)]
    unpickle = (time.perf_counter() - start) / 64
    concatenate = timed(concatenate_batches, parts) / 64
    summary = timed(summarise, concatenate_batches(parts)) / 64
    print(
        f"driver per 200 s episode: {len(blob) / 1e6:.2f} MB returned, unpickle "
        f"{unpickle * 1e3:.1f} ms, concatenate {concatenate * 1e3:.1f} ms, summary "
        f"{summary * 1e3:.1f} ms"
    )


if __name__ == "__main__":
    main()
