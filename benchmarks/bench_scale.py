"""How the project scales with N (prints figures, asserts nothing).

For each N (default 5, 10, 20, 50, 100: a 10 m grid with a 4-nearest graph on the paper's route
and obstacles, :func:`~uav_formation_env.scenarios.swarm_scenario`, local observation, UAVs
sensed within 25 m; N = 5 is the same grid family, not the paper's V, so that every row is one
family):

* episode-layer env-steps/s at B = 1 and B = 256 with random actions (one step of all N agents,
  observations included), and UAV-steps/s (env-steps/s x N) at B = 256: flat when the step's
  cost grows linearly in N;
* the reference DMPC (LFPIO) ms per control step at B = 1, and per UAV-step;
* every figure as a ratio to N = 5 measured in the same run;
* seconds to build and validate ``swarm_scenario(N)`` for the ``--build`` sizes (median of 5).

    python benchmarks/bench_scale.py [--sizes 5 10 20 50 100] [--seconds 2] [--dmpc-steps 5]
                                     [--build 1000]

The issue's targets: a DMPC cost per UAV-step at N = 100 within 10x of N = 5, and an env step
whose cost grows at most linearly in N.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from uav_formation_env.episode import FormationEpisodes
from uav_formation_env.policies import make_policy
from uav_formation_env.scenarios import swarm_scenario


def env_rate(scenario, batch: int, seconds: float) -> float:
    """env-steps/s (copies x steps per second) of the episode layer with random actions."""
    episodes = FormationEpisodes(scenario, batch, autoreset=True)
    episodes.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (64, batch, scenario.n_uav, 3))
    episodes.step(actions[0])
    count, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        episodes.step(actions[count % 64])
        count += 1
    return batch * count / (time.perf_counter() - start)


def dmpc_ms(scenario, steps: int) -> float:
    """Milliseconds per control step of LFPIO (B = 1), after one warm-up step."""
    episodes = FormationEpisodes(scenario, 1)
    policy = make_policy("lfpio", scenario)
    policy.reset(1, seeds=[0])
    step = episodes.reset(seed=0)
    step = episodes.step(policy.act_batch(step.observation, step.neighbour_index))
    start = time.perf_counter()
    for _ in range(steps):
        step = episodes.step(policy.act_batch(step.observation, step.neighbour_index))
    return 1e3 * (time.perf_counter() - start) / steps


def build_seconds(n_uav: int, repeats: int = 5) -> tuple[float, float]:
    """Median wall and CPU seconds of ``swarm_scenario(n_uav)`` (the shape, its graph and the
    validation)."""
    walls, cpus = [], []
    for _ in range(repeats):
        start, cpu = time.perf_counter(), time.process_time()
        swarm_scenario(n_uav)
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - cpu)
    return statistics.median(walls), statistics.median(cpus)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[5, 10, 20, 50, 100])
    parser.add_argument("--seconds", type=float, default=2.0, help="per env measurement")
    parser.add_argument("--dmpc-steps", type=int, default=5, help="timed DMPC steps per N")
    parser.add_argument("--build", type=int, nargs="*", default=[1000], help="N of build rows")
    args = parser.parse_args()
    for n in args.build:
        wall, cpu = build_seconds(n)
        print(
            f"swarm_scenario({n}) built and validated: {wall:.3f} s wall, {cpu:.3f} s CPU "
            "(medians of 5)"
        )
    rows = []
    for n in args.sizes:
        scenario = swarm_scenario(n)
        rows.append(
            (
                n,
                env_rate(scenario, 1, args.seconds),
                env_rate(scenario, 256, args.seconds),
                dmpc_ms(scenario, args.dmpc_steps),
            )
        )
        print(f"measured N = {n}", flush=True)
    if not rows:
        return
    base = rows[0]
    print(
        f"\n| N | env-steps/s B=1 | (vs N={base[0]}) | env-steps/s B=256 | (vs N={base[0]}) "
        f"| UAV-steps/s B=256 | (vs N={base[0]}) "
        f"| DMPC ms/step | per UAV-step ms | (vs N={base[0]}) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n, one, many, ms in rows:
        per_uav, base_per_uav = ms / n, base[3] / base[0]
        uav_rate, base_uav_rate = many * n, base[2] * base[0]
        print(
            f"| {n} | {one:,.0f} | {one / base[1]:.2f}x | {many:,.0f} | {many / base[2]:.2f}x "
            f"| {uav_rate:,.0f} | {uav_rate / base_uav_rate:.2f}x "
            f"| {ms:.1f} | {per_uav:.2f} | {per_uav / base_per_uav:.1f}x |"
        )


if __name__ == "__main__":
    main()
