"""NashDMPCPolicy on the whole paper scenario, closed loop through FormationSim.

Prints, per optimiser and observer setting: seconds per 1000-step episode and per control step
(policy alone and policy + simulator), trigger counts per UAV (docs/model.md §8, Table 2), the
minimum distance to the obstacle centres, and collisions (two UAVs closer than the scenario's 2 m).
Before the timed episodes of each optimiser and observer setting, a throwaway 2-step run loads
the compiled kernels (printed as the warm-up). Seeds run one after another as B = 1 episodes,
or all at once as B copies with ``--batched`` (one optimiser call per step for every copy:
seconds per episode = wall time / B).

    python benchmarks/bench_policy.py [--optimizers pio lfpio] [--observer on off]
                                      [--seeds 0 1] [--batched] [--steps 1000]
                                      [--set cost.separation=0 ...] [--numpy]

``--set`` overrides scenario fields (YAML values, e.g. ``--set cost.separation=0`` flies the paper's
J_i without the separation term); ``--numpy`` runs LFPIO without the compiled kernels.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import yaml

from uav_formation_env.config_io import paper_scenario, with_overrides
from uav_formation_env.core.obstacles import obstacle_distances
from uav_formation_env.episode import observations_of
from uav_formation_env.policies import optimizers
from uav_formation_env.policies.dmpc import NashDMPCPolicy
from uav_formation_env.policies.registry import DMPC_OPTIMIZERS, PAPER_OPTIMIZERS
from uav_formation_env.sim import FormationSim, StepResult


def observe(sim: FormationSim, result: StepResult) -> np.ndarray:
    """Every agent's observation (B, N, dim), built as the environment builds it."""
    return observations_of(sim, result)


def episode(
    optimizer: str,
    observer: bool,
    seeds: list[int],
    steps: int,
    population_cost: str,
    overrides: dict | None = None,
) -> dict:
    """Run B = len(seeds) copies for ``steps`` control steps; return the measurements."""
    scenario = with_overrides(paper_scenario(), {**(overrides or {}), "observer.enabled": observer})
    sim = FormationSim(scenario, batch_size=len(seeds))
    policy = NashDMPCPolicy(
        scenario, optimizer=optimizer, seed=seeds[0], population_cost=population_cost
    )
    result = sim.reset(seed=seeds)
    min_centre = np.full(len(seeds), np.inf)
    min_sep = np.full(len(seeds), np.inf)
    collision_steps = np.zeros(len(seeds), dtype=int)
    start, cpu = time.perf_counter(), time.process_time()
    for _ in range(steps):
        actions = policy.act_batch(observe(sim, result))
        result = sim.step(actions * sim.u_max)
        centre = obstacle_distances(result.z[..., :3], scenario.avoidance)  # (B, N, O)
        min_centre = np.minimum(min_centre, centre.min(axis=(1, 2), initial=np.inf))
        min_sep = np.minimum(min_sep, result.min_separation.min(axis=1))
        collision_steps += (result.min_separation < scenario.collision.uav_distance).any(axis=1)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    records = policy.records()
    return {
        "wall": wall,
        "cpu": cpu,
        "policy": float(records.wall_time.sum()),
        "triggers": policy.trigger_counts(),
        "evaluations": records.evaluations.sum(axis=(0, 2)),
        "min_centre": min_centre,
        "min_sep": min_sep,
        "collision_steps": collision_steps,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument(
        "--optimizers", nargs="+", default=list(PAPER_OPTIMIZERS), choices=DMPC_OPTIMIZERS
    )
    parser.add_argument("--observer", nargs="+", default=["on", "off"], choices=["on", "off"])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--batched", action="store_true", help="all seeds as B copies at once")
    parser.add_argument("--population-cost", default="quadratic", choices=["quadratic", "direct"])
    parser.add_argument(
        "--set", nargs="*", default=[], metavar="KEY=VALUE", help="scenario overrides"
    )
    parser.add_argument("--numpy", action="store_true", help="LFPIO without compiled kernels")
    args = parser.parse_args()
    if args.numpy:  # as if numba were missing (UAV_FORMATION_NO_NUMBA=1 before the import)
        optimizers.COMPILED_AVAILABLE = False
    overrides = {k: yaml.safe_load(v) for k, v in (item.split("=", 1) for item in args.set)}
    groups = [args.seeds] if args.batched else [[s] for s in args.seeds]
    print(
        f"{'optimizer':>9} {'obs':>3} {'seeds':>10} {'s/episode':>9} {'cpu s':>6} {'ms/step':>8} "
        f"{'policy ms':>9} {'triggers per UAV (mean over copies)':>38} {'mean':>6} "
        f"{'min d_o':>7} {'min sep':>7} {'coll':>4}"
    )
    for optimizer in args.optimizers:
        for observer in args.observer:
            # the compiled kernels' one-time load (numba's cache) in a throwaway run, so that
            # s/episode is the episode's own cost
            warm = episode(
                optimizer, observer == "on", groups[0], 2, args.population_cost, overrides
            )
            print(f"{'':>24} warm-up (2 steps, kernels loaded): {warm['wall']:.2f} s")
            for seeds in groups:
                out = episode(
                    optimizer, observer == "on", seeds, args.steps, args.population_cost, overrides
                )
                b = len(seeds)
                per_episode = out["wall"] / b * 1000 / args.steps
                cpu_episode = out["cpu"] / b * 1000 / args.steps
                per_step = 1e3 * out["wall"] / args.steps / b
                policy_step = 1e3 * out["policy"] / args.steps / b
                triggers = out["triggers"].mean(axis=0)
                print(
                    f"{optimizer:>9} {observer:>3} {','.join(map(str, seeds)):>10} "
                    f"{per_episode:>9.2f} {cpu_episode:>6.2f} {per_step:>8.2f} {policy_step:>9.2f} "
                    f"{' / '.join(f'{t:.1f}' for t in triggers):>38} {triggers.mean():>6.1f} "
                    f"{out['min_centre'].min():>7.2f} {out['min_sep'].min():>7.2f} "
                    f"{int(out['collision_steps'].sum()):>4}"
                    + (f"  per copy {out['collision_steps'].tolist()}" if b > 1 else "")
                )
    print(
        "s/episode and ms/step are per copy (wall / B), scaled to 1000 steps; 'cpu s' is the "
        "process's CPU time per episode (user + system: what a busy shared machine inflates "
        "least); 'policy ms' is "
        "NashDMPCPolicy.act_batch alone; min d_o = minimum distance to an obstacle centre [m]; "
        "min sep = minimum UAV separation [m]; coll = copy-steps with two UAVs closer than 2 m."
    )


if __name__ == "__main__":
    main()
