"""DAgger's two costs on this machine: labelling (the exact teacher flying a round's episodes) with
1, 2, ... worker processes, and fitting the MLP on the CPU and, where torch sees one, on CUDA, in
the same run, as ratios to one worker / the CPU (prints figures, asserts nothing).

    pip install -e ".[rl]" && python benchmarks/bench_dagger.py [--episodes 8] [--duration 40] \
        [--workers 1 2] [--samples 128000] [--hidden 512 512]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import torch

from uav_formation_baselines.imitation import ImitationConfig, fit, resolve_device
from uav_formation_baselines.imitation_data import collect_in_workers, worker_pool
from uav_formation_baselines.torch_policy import NormalisedMLP
from uav_formation_env.config_io import resolve_scenario, with_overrides


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=8, help="episodes labelled per timing")
    parser.add_argument("--duration", type=float, default=40.0, help="episode length [s]")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--samples", type=int, default=128_000, help="samples fitted")
    parser.add_argument("--hidden", type=int, nargs="+", default=[512, 512])
    args = parser.parse_args()
    scenario = with_overrides(
        resolve_scenario("paper"), {"duration": args.duration, "observation": {"kind": "local"}}
    )
    seeds = list(range(10_000, 10_000 + args.episodes))
    print(
        f"{os.cpu_count()} CPUs; exact teacher, {args.episodes} paper episodes of "
        f"{args.duration:g} s"
    )
    baseline = None
    for workers in args.workers:
        pool = worker_pool(workers)
        try:
            if pool is not None:  # start the processes (imports) outside the timing
                collect_in_workers(pool, workers, seeds[:workers], scenario=scenario,
                                   teacher_name="exact", n_steps=1)  # fmt: skip
            start = time.perf_counter()
            obs = collect_in_workers(pool, workers, seeds, scenario=scenario, teacher_name="exact")
            seconds = time.perf_counter() - start
        finally:
            if pool is not None:
                pool.shutdown()
        rate = len(obs[0]) / seconds
        baseline = baseline or rate
        print(f"labelling, {workers} worker(s): {rate:,.0f} UAV-steps/s ({rate / baseline:.2f}x)")

    rng = np.random.default_rng(0)
    data = rng.normal(size=(args.samples, obs[0].shape[1])).astype(np.float32)
    targets = rng.uniform(-1, 1, size=(args.samples, 3)).astype(np.float32)
    config = ImitationConfig(epochs=1, hidden=tuple(args.hidden))
    devices = ["cpu"] + (["cuda"] if resolve_device("auto") == "cuda" else [])
    print(f"torch CPU threads: {torch.get_num_threads()}")
    cpu_rate = None
    for device in devices:
        model = NormalisedMLP(data.mean(axis=0), data.std(axis=0), config.hidden)
        fit(model, data[:4096], targets[:4096], config, 0, device=device)  # warm-up
        start = time.perf_counter()
        fit(model, data, targets, config, 0, device=device)
        rate = args.samples / (time.perf_counter() - start)
        cpu_rate = cpu_rate or rate
        print(f"fit {args.hidden} MLP on {device}: {rate:,.0f} samples/s ({rate / cpu_rate:.2f}x)")


if __name__ == "__main__":
    main()
