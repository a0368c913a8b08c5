"""FormationSim throughput (env-steps/s = copies x steps / s), observer on, beside a bare kernel.

The reference is a bare numpy double-integrator kernel of the same size (N = 5 UAVs, ZOH step with a
random input), measured in the same run, so the ratio is robust to the machine's speed.

    python benchmarks/bench_sim.py [--batches 1 32 1024 4096] [--seconds 2]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from uav_formation_env.config_io import paper_scenario, with_overrides
from uav_formation_env.sim import FormationSim


def _rate(step, batch: int, seconds: float) -> float:
    step()  # warm-up
    count, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        step()
        count += 1
    return batch * count / (time.perf_counter() - start)


def bare_kernel(batch: int, seconds: float) -> float:
    rng = np.random.default_rng(0)
    p, v = np.zeros((batch, 5, 3)), np.zeros((batch, 5, 3))
    dt = 0.2

    def step() -> None:
        nonlocal p, v
        a = rng.uniform(-5, 5, size=(batch, 5, 3))
        p = p + v * dt + 0.5 * a * dt * dt
        v = v + a * dt

    return _rate(step, batch, seconds)


def sim_rate(batch: int, seconds: float, observer: bool) -> float:
    scenario = with_overrides(paper_scenario(), {"observer.enabled": observer})
    sim = FormationSim(scenario, batch_size=batch)
    sim.reset(seed=0)
    rng = np.random.default_rng(0)
    limit = scenario.n_steps - 1

    def step() -> None:
        if sim.last.step[0] >= limit:
            sim.reset(seed=0)
        sim.step(rng.uniform(-5, 5, size=(batch, scenario.n_uav, 3)))

    return _rate(step, batch, seconds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--batches", type=int, nargs="+", default=[1, 32, 1024, 4096])
    parser.add_argument("--seconds", type=float, default=2.0)
    args = parser.parse_args()
    print(f"{'B':>6} {'kernel':>12} {'sim obs on':>12} {'sim obs off':>12} {'on/kernel':>10}")
    for batch in args.batches:
        kernel = bare_kernel(batch, args.seconds)
        on = sim_rate(batch, args.seconds, observer=True)
        off = sim_rate(batch, args.seconds, observer=False)
        print(f"{batch:>6} {kernel:>12,.0f} {on:>12,.0f} {off:>12,.0f} {on / kernel:>10.3f}")
    print("units: env-steps/s (copies x control steps per second), N = 5 UAVs")


if __name__ == "__main__":
    main()
