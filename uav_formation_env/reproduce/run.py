"""Running the variants (in parallel processes) and writing the tables, summary and report."""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import queue as queue_module
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from uav_formation_env.config import Scenario
from uav_formation_env.config_io import resolve_scenario
from uav_formation_env.core.array_api import torch_device
from uav_formation_env.evaluation import (
    EpisodeBatch,
    json_ready,
    write_json,
    write_records,
)
from uav_formation_env.reproduce.figures import write_figures
from uav_formation_env.reproduce.nash_analysis import (
    NASH_FIGURE,
    nash_report_lines,
    nash_rows,
    plot_nash_gap,
    write_nash_table,
)
from uav_formation_env.reproduce.report import build_report
from uav_formation_env.reproduce.tables import build_summary, write_table2
from uav_formation_env.reproduce.variants import (
    GAME_VARIANTS,
    LABELS,
    VARIANTS,
    run_variant,
    variant_scenario,
    variant_spec,
)
from uav_formation_env.seeding import check_seed


def _worker(args: tuple) -> tuple[str, EpisodeBatch]:
    variant, base, seeds, duration, policy_seed, random, channel = args

    def report(done: int) -> None:
        channel.put(done)

    return variant, run_variant(variant, base, seeds, duration, policy_seed, report, random=random)


@dataclass
class Reproduction:
    """What :func:`reproduce` produced: the episode batches and the summary it wrote."""

    batches: dict[str, EpisodeBatch]
    summary: dict[str, Any]
    out: Path


def reproduce(
    out: str | Path,
    seeds: Sequence[int] = range(5),
    scenario: str | Path | Scenario = "paper",
    duration: float | None = None,
    jobs: int = 0,
    progress: bool = True,
    records: bool = False,
    policy_seed: int | None = None,
    variants: Sequence[str] = tuple(VARIANTS),
    game_variants: Sequence[str] = tuple(GAME_VARIANTS),
    backend: str = "local",
    address: str | None = None,
    chunk_size: int = 1,
    device: Any = None,
    random: str = "generator",
) -> Reproduction:
    """Fly the four variants on the same seeds and write the tables, figures and report.

    Args:
        out: output directory (created).
        seeds: the episode seeds, shared by every variant.
        scenario: base scenario (name, YAML path or object); the observer is set per variant.
        duration: episode length [s] (None: the scenario's, 200 s for the paper).
        jobs: variants run in parallel processes (1: one after the other in this process;
            0: one per available CPU, at most one per variant). The numbers do not depend on it.
        progress: tqdm progress bars.
        records: also write per-step CSVs per variant.
        policy_seed: a seed mixed into the DMPC optimisers' per-episode streams (None: the
            streams are seeded from the episode seeds alone, so an episode's numbers do not
            depend on which other seeds run beside it).
        variants: subset of :data:`VARIANTS` to run (all four for the report's comparison).
        game_variants: further solvers of the game for the Nash-gap comparison (observer on):
            names of :data:`GAME_VARIANTS` or paths of stable-baselines3 models; empty to skip.
            Every variant's Nash gap is measured at every step (``nash_gap.csv``,
            ``fig10_nash_gap.png``, a section of ``REPORT.md``).
        backend: ``"local"`` (processes on this machine, ``jobs``) or ``"ray"`` (every
            (variant, ``chunk_size`` seeds) a Ray task, on the cluster at ``address`` or a local
            Ray instance; :mod:`uav_formation_env.distributed`). The numbers do not depend on it.
            ``"torch"``: every variant's seeds as one batch of the torch episode layer on
            ``device``, the variants one after another in this process (the DMPC
            metaheuristics act on the device; :func:`~uav_formation_env.evaluation.run_episodes`).
            The numbers agree with the numpy backend's to rounding, which can grow over an
            episode (docs/architecture.md, "Backends").
        address: the Ray cluster (None: start a local instance).
        chunk_size: seeds per Ray task.
        device: the torch device with ``backend="torch"`` (None: CUDA if available, else the
            CPU); only with that backend.
        random: the DMPC optimisers' random numbers, ``"generator"`` (each episode's numpy
            generator: the paper reproduction's numbers) or ``"counter"`` (counter-based, drawn
            where the optimiser runs: the fast choice on a GPU); not with ``backend="ray"``.
    """
    if random != "generator" and backend == "ray":
        raise ValueError(f"random={random!r} is not available with backend='ray'")
    if backend not in ("local", "ray", "torch"):
        raise ValueError(f"backend must be 'local', 'ray' or 'torch', got {backend!r}")
    if device is not None and backend != "torch":
        raise ValueError(f"device={device!r} needs backend='torch' (got backend={backend!r})")
    if backend == "torch":
        device = torch_device(device)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    base = resolve_scenario(scenario)
    seeds = [check_seed(s, f"seeds[{k}]") for k, s in enumerate(seeds)]
    if not seeds or None in seeds:
        raise ValueError("seeds must be a non-empty list of non-negative ints")
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        raise ValueError(f"unknown variant(s) {unknown}; expected some of {list(VARIANTS)}")
    game_variants = [v for v in game_variants if v not in variants]
    for v in game_variants:
        variant_spec(v)  # raises for an unknown name or a missing model
    if int(jobs) <= 0:
        jobs = available_cpus()
    everything = [*variants, *game_variants]
    jobs = max(1, min(int(jobs), len(everything)))
    start = time.perf_counter()
    if backend == "ray":
        batches = _run_all_ray(everything, base, seeds, duration, policy_seed, progress, address,
                               chunk_size)  # fmt: skip
    elif backend == "torch":
        jobs = 1
        batches = {
            v: run_variant(v, base, seeds, duration, policy_seed, progress, "torch", device, random)
            for v in everything
        }
    else:
        batches = _run_all(everything, base, seeds, duration, policy_seed, jobs, progress, random)
    wall = time.perf_counter() - start
    all_batches = {v: batches[v] for v in everything}
    batches = {v: batches[v] for v in variants}

    summary = build_summary(batches, seeds, wall, jobs)
    nash = nash_rows(all_batches)
    summary["nash_gap"] = {row["variant"]: row for row in nash}
    summary = json_ready(summary)
    write_table2(batches, out / "table2.csv")
    write_nash_table(nash, out / "nash_gap.csv")
    write_json(summary, out / "summary.json")
    write_figures(batches, out)
    plot_nash_gap(all_batches, out / NASH_FIGURE)
    report = build_report(batches, summary) + "\n" + "\n".join(nash_report_lines(nash))
    (out / "REPORT.md").write_text(report)
    if records:
        for variant, batch in all_batches.items():
            name = variant if variant in LABELS else Path(variant).parent.name or "model"
            write_records(batch, out / f"records_{name}.csv")
    return Reproduction(batches, summary, out)


def _run_all(
    variants: list[str],
    base: Scenario,
    seeds: list[int],
    duration: float | None,
    policy_seed: int | None,
    jobs: int,
    progress: bool,
    random: str = "generator",
) -> dict[str, EpisodeBatch]:
    if jobs == 1:
        return {
            v: run_variant(v, base, seeds, duration, policy_seed, progress, random=random)
            for v in variants
        }
    # slowest first (LFPIO spends about twice PIO's evaluations)
    order = sorted(variants, key=lambda v: variant_spec(v)[0] not in ("lfpio", "nash"))
    n_steps = variant_scenario(base, variants[0], duration).n_steps
    context = multiprocessing.get_context("spawn")
    with context.Manager() as manager:
        channel = manager.Queue()
        bar = tqdm(
            total=n_steps * len(variants),
            desc=f"{len(variants)} variants x {len(seeds)} seeds",
            unit="step",
            disable=not progress,
        )
        results: dict[str, EpisodeBatch] = {}
        with ProcessPoolExecutor(max_workers=jobs, mp_context=context) as pool:
            futures = [
                pool.submit(_worker, (v, base, seeds, duration, policy_seed, random, channel))
                for v in order
            ]
            pending = set(futures)
            while pending:
                with contextlib.suppress(queue_module.Empty):
                    advance(bar, channel.get(timeout=0.2))
                for future in [f for f in pending if f.done()]:
                    pending.discard(future)
                    variant, batch = future.result()
                    results[variant] = batch
        bar.close()
    return results


def advance(bar: tqdm, steps: int) -> None:
    """``bar.update(steps)``, except that the first steps restart the bar's clock: the start-up
    (spawning the processes, imports, compilation) is not stepping, and counted as such it made
    the first ETA read hours."""
    if bar.n == 0:
        bar.reset(total=bar.total)
        bar.n = bar.last_print_n = int(steps)  # counted, but no rate from them
        bar.refresh()
    else:
        bar.update(steps)


def _run_all_ray(
    variants: list[str],
    base: Scenario,
    seeds: list[int],
    duration: float | None,
    policy_seed: int | None,
    progress: bool,
    address: str | None,
    chunk_size: int,
) -> dict[str, EpisodeBatch]:
    """Every (variant, seed chunk) as a Ray task, with the Nash gap measured (as locally)."""
    from uav_formation_env.distributed import ray_session, run_variants_ray

    jobs = {v: (variant_scenario(base, v, duration), variant_spec(v)[0]) for v in variants}
    with ray_session(address):
        return run_variants_ray(
            jobs,
            seeds,
            chunk_size=chunk_size,
            nash_gap=True,
            policy_seed=policy_seed,
            progress=progress,
            desc=f"{len(variants)} variants x {len(seeds)} seeds (ray)",
        )


def available_cpus() -> int:
    """CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


# ---------------------------------------------------------------------------------------- tables
