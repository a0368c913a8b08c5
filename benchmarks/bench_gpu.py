"""The torch backend against the numpy simulator and VMAS (prints figures, asserts nothing).

Rows, each measured in this run:

* the numpy episode layer at B = 1 and B = 4,096 (the reference every ratio is taken against);
* the torch episode layer on the CPU at B = 4,096 (eager), same scenario, same physics;
* on CUDA, when a GPU is present: the torch episode layer at B = 4,096 ... 1,048,576
  (``--batches``, eager; ``torch.compile`` of the step is not built yet), and VMAS
  ``simple_spread`` and ``navigation`` (N = 5 agents) at the same B when ``vmas`` is installed.

Without a GPU it says so and measures the CPU rows only. Every figure is env-steps/s (copies x
steps per second; one env-step moves all N UAVs, observations, rewards and the 20-tick observer
included) with random actions and per-copy autoreset.

    python benchmarks/bench_gpu.py [--scenario paper] [--seconds 3] [--batches 4096 65536 262144]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from uav_formation_env.config_io import resolve_scenario
from uav_formation_env.episode import FormationEpisodes


def episode_rate(scenario, batch: int, seconds: float, backend: str, device=None) -> float:
    """env-steps/s of the episode layer with random actions in [-1, 1] and autoreset."""
    episodes = FormationEpisodes(scenario, batch, autoreset=True, backend=backend, device=device)
    episodes.reset(seed=0)
    n = scenario.n_uav
    if backend == "torch":
        import torch

        generator = torch.Generator(device=device).manual_seed(0)
        actions = [
            torch.rand((batch, n, 3), generator=generator, device=device, dtype=torch.float64) * 2
            - 1
            for _ in range(8)
        ]
        synchronize = torch.cuda.synchronize if str(device).startswith("cuda") else lambda: None
    else:
        rng = np.random.default_rng(0)
        actions = [rng.uniform(-1, 1, (batch, n, 3)) for _ in range(8)]
        synchronize = lambda: None  # noqa: E731
    episodes.step(actions[0])  # warm-up
    synchronize()
    count, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        episodes.step(actions[count % 8])
        count += 1
    synchronize()
    return batch * count / (time.perf_counter() - start)


def vmas_rate(name: str, batch: int, seconds: float, device: str) -> float | None:
    """env-steps/s of a VMAS scenario (N = 5 agents) with random actions, or None without vmas."""
    try:
        import torch
        import vmas
    except ImportError:
        return None
    env = vmas.make_env(name, num_envs=batch, device=device, continuous_actions=True, n_agents=5)
    env.reset()
    actions = [torch.rand((batch, 2), device=device) * 2 - 1 for _ in env.agents]
    env.step(actions)
    torch.cuda.synchronize()
    count, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        env.step(actions)
        count += 1
    torch.cuda.synchronize()
    return batch * count / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="paper")
    parser.add_argument("--seconds", type=float, default=3.0, help="per measurement")
    parser.add_argument("--cpu-batch", type=int, default=4096)
    parser.add_argument("--batches", type=int, nargs="+", default=[4096, 65536, 262144, 1048576])
    args = parser.parse_args()
    scenario = resolve_scenario(args.scenario)
    rows: list[tuple[str, int, float | None]] = []
    rows.append(("numpy", 1, episode_rate(scenario, 1, args.seconds, "numpy")))
    reference = episode_rate(scenario, args.cpu_batch, args.seconds, "numpy")
    rows.append(("numpy", args.cpu_batch, reference))
    try:
        import torch
    except ImportError:
        torch = None
        print("torch is not installed: the torch rows are not measured")
    if torch is not None:
        torch.set_num_threads(1)  # one core, as the numpy rows
        cpu = episode_rate(scenario, args.cpu_batch, args.seconds, "torch", "cpu")
        rows.append(("torch cpu (1 thread)", args.cpu_batch, cpu))
        if torch.cuda.is_available():
            for batch in args.batches:
                rows.append(
                    (
                        "torch cuda",
                        batch,
                        episode_rate(scenario, batch, args.seconds, "torch", "cuda"),
                    )
                )
                for name in ("simple_spread", "navigation"):
                    rows.append(
                        (f"vmas {name}", batch, vmas_rate(name, batch, args.seconds, "cuda"))
                    )
        else:
            print("no CUDA device: the GPU rows (torch cuda, VMAS) are not measured")
    print(f"\nscenario {scenario.name!r}, N = {scenario.n_uav}, {args.seconds:.1f} s per row\n")
    print(f"| backend | B | env-steps/s | vs numpy B={args.cpu_batch} |")
    print("|---|---:|---:|---:|")
    for name, batch, rate in rows:
        if rate is None:
            print(f"| {name} | {batch} | not installed | |")
        else:
            print(f"| {name} | {batch} | {rate:,.0f} | {rate / reference:.2f}x |")


if __name__ == "__main__":
    main()
