"""BenchMARL training throughput on our task and on VMAS ``navigation`` in the same run.

Both tasks are trained by the same BenchMARL experiment settings
(:func:`uav_formation_baselines.benchmarl_train.make_experiment` with the config of
``baselines/hyperparams/benchmarl.yml``): the same algorithm, MLP, batch and minibatch sizes,
one torch thread, CPU. Ours is the batched torch env of the paper scenario (N = 5, observer on,
1000-step episodes); VMAS ``navigation`` runs with ``n_agents = 5`` (its default scenario
otherwise, 100-step episodes). A few iterations each; the time is BenchMARL's ``run()`` (collection
and training together) after one warm-up iteration. Prints frames/s and agent-steps/s and the ratio
ours / VMAS, robust to the machine's speed. Asserts nothing.

    pip install -e ".[benchmarl,bench]"   # vmas for the peer (skipped without it)
    python benchmarks/bench_marl.py [--algos mappo ippo masac] [--iterations 3]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from typing import Any

import torch

from uav_formation_baselines.benchmarl_train import (
    formation_task,
    load_config,
    make_experiment,
)


def vmas_navigation(n_agents: int) -> Any | None:
    """BenchMARL's VMAS navigation task with ``n_agents``, or None without vmas."""
    try:
        import vmas  # noqa: F401
        from benchmarl.environments import VmasTask
    except ImportError:
        return None
    task = VmasTask.NAVIGATION.get_from_yaml()
    task.config["n_agents"] = n_agents
    return task


def frames_per_second(algo: str, task: Any, iterations: int, seed: int = 0) -> float:
    """Frames (env steps of one copy) per second of ``iterations`` BenchMARL iterations after a
    one-iteration warm-up."""
    config = load_config(algo)
    with tempfile.TemporaryDirectory() as folder:
        warm = make_experiment(algo, task, _frames(config, 1), seed, folder)
        warm.run()
        experiment = make_experiment(algo, task, _frames(config, iterations), seed, folder)
        start = time.perf_counter()
        experiment.run()
        seconds = time.perf_counter() - start
        return experiment.total_frames / seconds


def _frames(config: Any, iterations: int) -> Any:
    from dataclasses import replace

    return replace(config, frames=iterations * config.frames_per_batch)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--algos", nargs="+", default=["mappo", "ippo", "masac"])
    parser.add_argument("--iterations", type=int, default=3)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    n_agents = 5
    peer = vmas_navigation(n_agents)
    if peer is None:
        print("vmas is not installed: only our task is measured (pip install vmas)")
    print(
        f"BenchMARL, {args.iterations} iterations after a warm-up, {args.threads} torch thread(s)"
    )
    print(
        "| algorithm | ours frames/s | ours agent-steps/s | VMAS navigation frames/s | "
        "VMAS agent-steps/s | ours / VMAS |"
    )
    print("|---|---:|---:|---:|---:|---:|")
    for algo in args.algos:
        ours = frames_per_second(algo, formation_task("paper", load_config(algo)), args.iterations)
        theirs = frames_per_second(algo, peer, args.iterations) if peer is not None else None
        peer_cells = (
            "- | - | -"
            if theirs is None
            else f"{theirs:,.0f} | {theirs * n_agents:,.0f} | {ours / theirs:.2f}x"
        )
        print(f"| {algo} | {ours:,.0f} | {ours * n_agents:,.0f} | {peer_cells} |", flush=True)


if __name__ == "__main__":
    main()
