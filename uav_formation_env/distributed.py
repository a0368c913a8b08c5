"""Ray backend: evaluations and the paper reproduction fanned out as Ray tasks.

Every episode depends on its seed alone (one random stream per copy in the simulator and in the
stochastic policies), so a batch of seeds can be cut into chunks, each chunk flown by a Ray task
on any worker, and the chunks concatenated (:func:`~uav_formation_env.evaluation.
concatenate_batches`): the records and summaries equal the local backend's, up to wall times.

- :func:`ray_session`: connect to a cluster (``address``, e.g. ``"ray://head:10001"`` or
  ``"auto"``) or start a local Ray instance; shut it down afterwards only if it was started here.
- :func:`run_episodes_ray`: :func:`~uav_formation_env.evaluation.run_episodes` with the seeds
  spread over tasks of ``chunk_size`` seeds each (1 CPU per task), with a progress bar over
  episodes.
- :func:`run_variants_ray`: several policies (the reproduction's variants) at once, every
  (variant, chunk) a task.

Tasks build their policy from its name or model path, so a model file must be readable at the
same path on every worker (a shared file system, or the same checkout everywhere). Ray is the
``[ray]`` extra; nothing else in the package imports it.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, Sequence
from typing import Any

from tqdm import tqdm

from uav_formation_env.config import Scenario
from uav_formation_env.config_io import with_overrides
from uav_formation_env.evaluation import EpisodeBatch, concatenate_batches, run_episodes
from uav_formation_env.extras import require
from uav_formation_env.policies.registry import make_policy

__all__ = ["chunks", "ray_session", "run_episodes_ray", "run_variants_ray"]


@contextlib.contextmanager
def ray_session(address: str | None = None, num_cpus: int | None = None) -> Iterator[Any]:
    """Ray, initialised: on the cluster at ``address``, or a local instance (``num_cpus``: its
    CPUs, None: all). An instance started here is shut down on exit.

    Yields:
        The ``ray`` module.
    """
    ray = require("ray", "--backend ray")
    started = not ray.is_initialized()
    if started:
        # no usage reports (no network here); a throwaway local instance needs no auth token
        os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
        if address is None:
            os.environ.setdefault("RAY_AUTH_MODE", "disabled")
        ray.init(
            address=address,
            num_cpus=None if address else num_cpus,
            include_dashboard=False,
            log_to_driver=False,
            configure_logging=False,
        )
    try:
        yield ray
    finally:
        if started:
            ray.shutdown()


def chunks(seeds: Sequence[int], chunk_size: int) -> list[list[int]]:
    """The seeds in consecutive chunks of at most ``chunk_size``."""
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1:
        raise ValueError(f"chunk_size must be an integer >= 1, got {chunk_size!r}")
    seeds = list(seeds)
    return [seeds[i : i + chunk_size] for i in range(0, len(seeds), chunk_size)]


def _fly(
    label: str,
    scenario: Scenario,
    policy: str,
    seeds: list[int],
    algo: str | None,
    duration: float | None,
    nash_gap: bool,
    policy_seed: int | None,
) -> EpisodeBatch:
    """One task: build the policy for the episode length it flies, fly the seeds."""
    if duration is not None:
        scenario = with_overrides(scenario, {"duration": float(duration)})
    built = make_policy(policy, scenario, seed=policy_seed, algo=algo)
    return run_episodes(scenario, built, seeds, policy_name=label, nash_gap=nash_gap)


def run_variants_ray(
    jobs: dict[str, tuple[Scenario, str]],
    seeds: Sequence[int],
    *,
    chunk_size: int = 1,
    duration: float | None = None,
    algo: str | None = None,
    nash_gap: bool = False,
    policy_seed: int | None = None,
    progress: bool = True,
    desc: str = "ray",
) -> dict[str, EpisodeBatch]:
    """Fly every (label, (scenario, policy)) of ``jobs`` on ``seeds``, each (label, chunk) as a
    Ray task (call inside :func:`ray_session`).

    Returns:
        label -> the batch of all seeds, in order (``policy_name`` is the label).
    """
    ray = require("ray", "--backend ray")
    task = ray.remote(num_cpus=1)(_fly)
    parts = chunks(seeds, chunk_size)
    refs = {
        task.remote(label, scenario, policy, chunk, algo, duration, nash_gap, policy_seed): (
            label,
            k,
        )
        for label, (scenario, policy) in jobs.items()
        for k, chunk in enumerate(parts)
    }
    done: dict[tuple[str, int], EpisodeBatch] = {}
    total = len(jobs) * sum(len(chunk) for chunk in parts)
    with tqdm(total=total, desc=desc, unit="episode", disable=not progress) as bar:
        pending = list(refs)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            label, k = refs[ready[0]]
            done[label, k] = ray.get(ready[0])
            bar.update(len(parts[k]))
    return {
        label: concatenate_batches([done[label, k] for k in range(len(parts))]) for label in jobs
    }


def run_episodes_ray(
    scenario: Scenario,
    policy: str,
    seeds: Sequence[int],
    **options: Any,
) -> EpisodeBatch:
    """:func:`~uav_formation_env.evaluation.run_episodes` of the policy named ``policy`` (a
    registered name or a model path), its seeds spread over Ray tasks (call inside
    :func:`ray_session`); ``options`` as for :func:`run_variants_ray`."""
    return run_variants_ray({policy: (scenario, policy)}, seeds, **options)[policy]
