"""The torch backend against the numpy simulator and VMAS (prints figures, asserts nothing).

Rows, each measured in this run:

* the numpy episode layer at B = 1 and B = 4,096 (the reference every ratio is taken against);
* the torch episode layer on the CPU at B = 4,096: eager, with ``compile=True`` (the whole step
  through ``torch.compile``; its compilation is not timed), and also with ``noise="counter"``
  (the disturbance noise drawn on the device), same physics; ``--repeats`` rounds of these rows
  and the numpy row, with the median of the per-round ratios;
* on CUDA, when a GPU is present: the torch episode layer at B = 4,096 ... 1,048,576
  (``--batches``, eager with host noise, and compiled with counter noise), and VMAS
  ``simple_spread`` and ``navigation`` (N = 5 agents) at the same B when ``vmas`` is installed.

Every figure is env-steps/s (copies x steps per second; one env-step moves all N UAVs,
observations, rewards and the 20-tick observer included) with random actions and per-copy
autoreset.

Then the reference policy (LFPIO DMPC with the observer, ``--dmpc-batch`` copies, the policy and
the episode layer together, seconds per control step): numpy with the numpy generators (the
reference), torch on the CPU with the same generators and with counter draws, and on CUDA with
both; and on CUDA the paper reproduction, ``uav-formation reproduce --backend torch
--random-source counter`` of the 4 variants x ``--reproduce-seeds`` seeds (200 s episodes).

Last, the in-process RL trainer (``uav_formation_baselines.onpolicy``, PPO on the paper's training
task, shipped hyper-parameters, no evaluations): agent-steps/s at ``--trainer-copies`` copies, on
the numpy episode layer on the CPU and on the torch episode layer on CUDA.

Without a GPU it says so and measures the CPU rows only. ``--parts`` picks the tables (``env``,
``trainer``, ``dmpc``) and the devices of their rows (``cpu``, ``cuda``; the numpy reference rows
are always measured), e.g. the CPU rows in one process and the CUDA rows in another, at the same
time on a many-core machine.

    python benchmarks/bench_gpu.py [--scenario paper] [--seconds 3] [--repeats 3]
                                   [--batches 4096 65536 262144]
                                   [--dmpc-batch 100] [--dmpc-steps 10] [--reproduce-seeds 100]
                                   [--parts env trainer dmpc cpu cuda] [--trainer-copies 128 4096]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from uav_formation_env.config_io import resolve_scenario
from uav_formation_env.episode import FormationEpisodes
from uav_formation_env.sim_options import SimOptions


def episode_rate(
    scenario,
    batch: int,
    seconds: float,
    backend: str,
    device=None,
    compile: bool = False,
    noise: str = "generator",
) -> float:
    """env-steps/s of the episode layer with random actions in [-1, 1] and autoreset."""
    episodes = FormationEpisodes(
        scenario,
        batch,
        autoreset=True,
        options=SimOptions(backend, device, compile, noise),
    )
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


def dmpc_step_seconds(batch: int, steps: int, backend: str, device=None, random="generator"):
    """Seconds per control step of the LFPIO DMPC and the episode layer, B copies of the paper
    scenario (after 3 warm-up steps, so the first triggers and allocations are not counted)."""
    from uav_formation_env.config_io import paper_scenario
    from uav_formation_env.policies.dmpc import NashDMPCPolicy

    scenario = paper_scenario()
    episodes = FormationEpisodes(scenario, batch, options=SimOptions(backend, device))
    policy = NashDMPCPolicy(scenario, "lfpio", random=random)
    seeds = list(range(batch))
    policy.reset(batch, seeds=seeds)
    step = episodes.reset(seed=seeds)
    synchronize = lambda: None  # noqa: E731
    if str(device).startswith("cuda"):
        import torch

        synchronize = torch.cuda.synchronize
    for k in range(steps + 3):
        if k == 3:
            synchronize()
            start = time.perf_counter()
        step = episodes.step(policy.act_batch(step.observation))
    synchronize()
    return (time.perf_counter() - start) / steps


def reproduce_seconds(seeds: int, device: str) -> float:
    """Wall seconds of the paper reproduction's 4 variants x ``seeds`` seeds on the torch backend
    with counter draws (no game variants, no progress bars)."""
    import tempfile

    from uav_formation_env.reproduce import reproduce

    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as out:
        reproduce(
            out,
            seeds=range(seeds),
            progress=False,
            game_variants=(),
            backend="torch",
            device=device,
            random="counter",
        )
    return time.perf_counter() - start


def trainer_rate(copies: int, updates: int, device: str) -> float:
    """Agent-steps/s of the in-process PPO trainer on the paper's training task: ``updates``
    updates of ``copies`` copies after one warm-up update (the numpy episode layer on the CPU,
    the torch one elsewhere; one torch thread)."""
    import tempfile

    from uav_formation_baselines.onpolicy_config import load_config
    from uav_formation_baselines.onpolicy_trainer import OnPolicyTrainer, build_scenario

    overrides = {"copies": copies, "eval_every": 0, "eval_seeds": 1}
    config = load_config("ppo", overrides, None)
    scenario = build_scenario("paper", config)
    with tempfile.TemporaryDirectory() as out:
        trainer = OnPolicyTrainer("ppo", scenario, config, 0, 1, out, device)
        trainer.train(progress=False)  # the warm-up update (and one evaluation, not timed)
        wall, frames = trainer.wall, trainer.frames
        trainer.updates += updates
        trainer.train(progress=False)
        return (trainer.frames - frames) / (trainer.wall - wall)


def trainer_rows(args, parts: set[str], cuda: bool) -> None:
    """The RL trainer's table (agent-steps/s): the numpy rows with ``cpu`` in ``--parts``, the
    CUDA rows with ``cuda``."""
    print("\nin-process PPO trainer, paper training task, shipped hyper-parameters\n")
    print("| episode layer | copies | agent-steps/s |")
    print("|---|---:|---:|")
    devices = ["cpu"] if "cpu" in parts else []
    devices += ["cuda"] if cuda and "cuda" in parts else []
    for copies in args.trainer_copies:
        for device in devices:
            rate = trainer_rate(copies, args.trainer_updates, device)
            label = "numpy, cpu" if device == "cpu" else "torch, cuda"
            print(f"| {label} | {copies} | {rate:,.0f} |", flush=True)
    if not cuda and "cuda" in parts:
        print("\nno CUDA device: the trainer's CUDA rows are not measured")


def dmpc_rows(args, parts: set[str], cuda: bool) -> None:
    """The reference policy's table (seconds per control step, ratio to numpy): numpy always,
    the torch CPU rows with ``cpu`` in ``--parts``, the CUDA rows and the reproduction with
    ``cuda``."""
    cases = [("numpy, generator", "numpy", None, "generator")]
    if "cpu" in parts:
        cases += [
            ("torch cpu, generator", "torch", "cpu", "generator"),
            ("torch cpu, counter", "torch", "cpu", "counter"),
        ]
    cuda = cuda and "cuda" in parts
    if cuda:
        cases += [
            ("torch cuda, generator", "torch", "cuda", "generator"),
            ("torch cuda, counter", "torch", "cuda", "counter"),
        ]
    print(f"\nLFPIO DMPC + episode layer, paper scenario, B = {args.dmpc_batch} copies\n")
    print("| backend, random numbers | s per control step | vs numpy |")
    print("|---|---:|---:|")
    reference = None
    for label, backend, device, random in cases:
        seconds = dmpc_step_seconds(args.dmpc_batch, args.dmpc_steps, backend, device, random)
        reference = reference or seconds
        print(f"| {label} | {seconds:.3f} | {reference / seconds:.2f}x |", flush=True)
    if cuda and args.reproduce_seeds > 0:
        wall = reproduce_seconds(args.reproduce_seeds, "cuda")
        print(
            f"\nreproduce --backend torch --device cuda --random-source counter, 4 variants x "
            f"{args.reproduce_seeds} seeds: {wall:.1f} s"
        )
    elif "cuda" in parts:
        print("\nno CUDA device: the CUDA DMPC rows and the reproduction's time are not measured")


def episode_rows(args, scenario, parts: set[str], torch) -> None:
    """The episode layer's table (env-steps/s, ratio to numpy at ``--cpu-batch``), a row printed
    as soon as it is measured. The CPU rows at ``--cpu-batch`` are measured in ``--repeats``
    rounds, numpy first in each: the median of each row, and the median of its per-round ratios
    to numpy (the load of a shared machine moves both alike)."""
    batch = args.cpu_batch
    cases = [("numpy", "numpy", False, "generator")]
    if torch is not None and "cpu" in parts:
        cases += [
            ("torch cpu (1 thread)", "torch", False, "generator"),
            ("torch cpu (1 thread), compiled", "torch", True, "generator"),
            ("torch cpu (1 thread), compiled, counter noise", "torch", True, "counter"),
        ]
    rounds = []
    for _ in range(args.repeats):
        rounds.append(
            [
                episode_rate(scenario, batch, args.seconds, backend, "cpu", compile_, noise)
                for _, backend, compile_, noise in cases
            ]
        )
    reference = float(np.median([r[0] for r in rounds]))
    print(f"\nscenario {scenario.name!r}, N = {scenario.n_uav}, {args.seconds:.1f} s per row")
    print(f"{args.repeats} rounds; the ratio is the median of the per-round ratios\n")
    print(f"| backend | B | env-steps/s | vs numpy B={batch} |")
    print("|---|---:|---:|---:|")

    def row(name: str, size: int, rate: float | None, ratio: float | None = None) -> None:
        if rate is None:
            print(f"| {name} | {size} | not installed | |", flush=True)
            return
        ratio = rate / reference if ratio is None else ratio
        print(f"| {name} | {size} | {rate:,.0f} | {ratio:.2f}x |", flush=True)

    if "cpu" in parts:
        row("numpy", 1, episode_rate(scenario, 1, args.seconds, "numpy"))
    for k, (label, *_) in enumerate(cases):
        rates = [r[k] for r in rounds]
        ratio = float(np.median([r[k] / r[0] for r in rounds]))
        row(label, batch, float(np.median(rates)), ratio)
    if torch is not None and "cuda" in parts and torch.cuda.is_available():
        for size in args.batches:
            for compile_, noise in ((False, "generator"), (True, "counter")):
                rate = episode_rate(scenario, size, args.seconds, "torch", "cuda", compile_, noise)
                row("torch cuda" + (", compiled, counter noise" if compile_ else ""), size, rate)
            for name in ("simple_spread", "navigation"):
                row(f"vmas {name}", size, vmas_rate(name, size, args.seconds, "cuda"))
    elif "cuda" in parts:
        print("no CUDA device: the GPU rows (torch cuda, VMAS) are not measured")


PARTS = ("env", "trainer", "dmpc", "cpu", "cuda")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="paper")
    parser.add_argument("--seconds", type=float, default=3.0, help="per measurement")
    parser.add_argument("--cpu-batch", type=int, default=4096)
    parser.add_argument("--repeats", type=int, default=3, help="rounds of the CPU rows")
    parser.add_argument("--batches", type=int, nargs="+", default=[4096, 65536, 262144, 1048576])
    parser.add_argument("--dmpc-batch", type=int, default=100, help="copies of the DMPC rows")
    parser.add_argument("--dmpc-steps", type=int, default=10, help="control steps per DMPC row")
    parser.add_argument("--reproduce-seeds", type=int, default=100, help="seeds (CUDA only)")
    parser.add_argument("--trainer-copies", type=int, nargs="+", default=[128, 4096])
    parser.add_argument("--trainer-updates", type=int, default=5, help="timed updates per row")
    parser.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS))
    args = parser.parse_args()
    parts = set(args.parts)
    scenario = resolve_scenario(args.scenario)
    try:
        import torch
    except ImportError:
        torch = None
        print("torch is not installed: the torch rows are not measured")
    else:
        torch.set_num_threads(1)  # one core, as the numpy rows
    cuda = torch is not None and torch.cuda.is_available()
    if "env" in parts:
        episode_rows(args, scenario, parts, torch)
    if torch is not None and "trainer" in parts:
        trainer_rows(args, parts, cuda)
    if torch is not None and "dmpc" in parts and args.dmpc_steps > 0:
        dmpc_rows(args, parts, cuda)


if __name__ == "__main__":
    main()
