"""Environment throughput with random actions (prints figures, asserts nothing).

* ``uav_formation_v0`` ParallelEnv on the paper scenario (N = 5), observer on and, for information,
  off: env-steps/s (one ``step()`` of all agents = one env-step), episode resets included.
* mpe2's ``simple_spread_v3`` ParallelEnv (N = 5, ``continuous_actions=True``, ``max_cycles=1000``
  to match the paper's 1000-step episodes) in the same run, when ``mpe2`` is importable, and the
  ratio ours / mpe2 (robust to the machine's speed).
* The SB3 VecEnv at B = 1024 and 4096 copies: env-steps/s = copies x steps per second (each copy
  is N = 5 VecEnv entries), auto-resets included.

    python benchmarks/bench_env.py [--seconds 3] [--repeats 1] [--batches 1024 4096]

On a shared, noisy machine use ``--repeats 3`` (or more): ours and mpe2 are then measured
alternately that many times and the median of the per-round ratios is printed as well.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np

from uav_formation_env import parallel_env, vec_env


def _rate(step: Callable[[], None], per_call: int, seconds: float) -> float:
    """Calls of ``step`` per second over about ``seconds`` (after one warm-up), times per_call."""
    step()
    count, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        step()
        count += 1
    return per_call * count / (time.perf_counter() - start)


def parallel_rate(env, low: float, high: float, seconds: float) -> float:
    """env-steps/s of a PettingZoo ParallelEnv with uniform random actions in [low, high]."""
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    shapes = {a: env.action_space(a).shape for a in env.possible_agents}

    def step() -> None:
        if not env.agents:
            env.reset()
        env.step({a: rng.uniform(low, high, shapes[a]).astype(np.float32) for a in env.agents})

    return _rate(step, 1, seconds)


def ours_rate(observer: bool, seconds: float) -> float:
    return parallel_rate(parallel_env("paper", observer__enabled=observer), -1.0, 1.0, seconds)


def mpe2_rate(seconds: float) -> float | None:
    try:
        from mpe2 import simple_spread_v3
    except ImportError:
        return None
    env = simple_spread_v3.parallel_env(N=5, continuous_actions=True, max_cycles=1000)
    return parallel_rate(env, 0.0, 1.0, seconds)


def vec_rate(batch: int, seconds: float) -> float:
    venv = vec_env("paper", num_copies=batch)
    venv.seed(0)
    venv.reset()
    rng = np.random.default_rng(0)

    def step() -> None:
        venv.step(rng.uniform(-1.0, 1.0, size=(venv.num_envs, 3)).astype(np.float32))

    return _rate(step, batch, seconds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--repeats", type=int, default=1, help="alternating rounds of ours/mpe2")
    parser.add_argument("--batches", type=int, nargs="+", default=[1024, 4096])
    args = parser.parse_args()

    print("ParallelEnv, random actions, N = 5 (env-steps/s, resets included)")
    ons, mpes = [], []
    for _ in range(max(1, args.repeats)):
        ons.append(ours_rate(observer=True, seconds=args.seconds))
        mpes.append(mpe2_rate(args.seconds))
    on = statistics.median(ons)
    off = ours_rate(observer=False, seconds=args.seconds)
    print(f"  uav_formation_v0 paper, observer on : {on:>10,.0f}")
    print(f"  uav_formation_v0 paper, observer off: {off:>10,.0f}  (for information)")
    if mpes[0] is None:
        print("  mpe2 simple_spread_v3: skipped (mpe2 is not importable)")
    else:
        mpe = statistics.median(mpes)
        print(f"  mpe2 simple_spread_v3 (continuous) : {mpe:>10,.0f}")
        print(f"  ratio ours (observer on) / mpe2    : {on / mpe:>10.3f}")
        if len(ons) > 1:
            ratios = [a / b for a, b in zip(ons, mpes)]
            spread = ", ".join(f"{r:.2f}" for r in ratios)
            median = statistics.median(ratios)
            print(f"  median of per-round ratios         : {median:>10.3f}  ({spread})")

    print("SB3 VecEnv, paper scenario, observer on, random actions")
    print(f"  {'B':>6} {'env-steps/s':>13} {'agent-steps/s':>14}")
    for batch in args.batches:
        rate = vec_rate(batch, args.seconds)
        print(f"  {batch:>6} {rate:>13,.0f} {5 * rate:>14,.0f}")
    print("env-step = one control step of one scenario copy (all 5 UAVs)")


if __name__ == "__main__":
    main()
