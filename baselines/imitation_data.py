"""DAgger's data: episodes flown by the teacher or a learner, each UAV-step labelled by the teacher.

:func:`collect` flies one episode per seed and labels it; :func:`collect_in_workers` splits the
seeds over worker processes. Each episode is named by its seed alone (its scene, the teacher's
optimiser streams and the teacher-or-learner coin flips all come from it), and the samples come
episode by episode in the order of the seeds, so the data do not depend on how the seeds were
batched or split over workers.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import Executor, ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np

from uav_formation_env.config import Scenario
from uav_formation_env.episode import FormationEpisodes
from uav_formation_env.evaluation import EpisodeBatch, run_episode_groups
from uav_formation_env.policies import make_policy
from uav_formation_env.policies.dmpc import NashDMPCPolicy
from uav_formation_env.policies.shield import SafetyShield
from uav_formation_env.scenes import seeds_by_n_uav

__all__ = ["collect", "collect_in_workers", "fly", "fly_in_workers", "worker_pool"]

Samples = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def collect(
    scenario: Scenario,
    teacher_name: str,
    seeds: Sequence[int],
    teacher_threshold: float = 0.0,
    learner: Any | str | Path | None = None,
    teacher_probability: float = 1.0,
    mix_seed: int = 0,
    n_steps: int | None = None,
    teacher_scenario: Scenario | None = None,
    shield: bool = False,
) -> Samples:
    """Fly one episode per seed and label every UAV-step with the teacher's action.

    Args:
        scenario: the scenario (any N; groups of equal N fly as one batch each).
        teacher_name: the reference DMPC solver that labels.
        seeds: episode seeds.
        teacher_threshold: its event-trigger threshold [-].
        learner: a policy with ``act_batch(obs)``, a saved policy's path (loaded with
            ``make_policy``, so that it can be sent to a worker process), or None (the teacher
            flies alone).
        teacher_probability: chance that a copy executes the teacher's action at a step (the
            learner's otherwise).
        mix_seed: seed of the coin flips; episode ``s`` flips its own coins from
            ``default_rng([mix_seed, s])``.
        n_steps: control steps flown per episode (None: the whole episode).
        teacher_scenario: the scenario the teacher plans with (None: ``scenario``); it must
            observe as ``scenario`` does (e.g. its J_i alone differs).
        shield: the learner acts behind the safety shield
            (:class:`~uav_formation_env.policies.shield.SafetyShield`), so that the episodes
            visit the states the shielded learner leads to; the labels stay the teacher's.

    Returns:
        ``(obs (M, dim) float32, actions (M, 3) float32, nearest (M,) [m], clearance (M,) [m])``
        ordered by episode (as ``seeds``), then step, then UAV; ``nearest`` is the distance from
        the UAV to its nearest other UAV, ``clearance`` to the nearest obstacle surface (inf
        without obstacles).
    """
    learner = _learner(learner, scenario, shield)
    steps = scenario.n_steps if n_steps is None else min(n_steps, scenario.n_steps)
    by_seed: dict[int, Samples] = {}
    for n_uav, group in seeds_by_n_uav(scenario, list(seeds)).items():
        episodes = FormationEpisodes(scenario, len(group), fly_on_after_collision=True, n_uav=n_uav)
        teacher = NashDMPCPolicy(
            scenario if teacher_scenario is None else teacher_scenario,
            teacher_name,
            threshold=teacher_threshold,
        )
        teacher.reset(len(group), seeds=group)
        step = episodes.reset(seed=group)
        links = getattr(teacher, "needs_neighbour_index", False)
        # (B, steps): one stream per episode, drawn once here rather than per copy and step
        coins = np.stack([np.random.default_rng([mix_seed, s]).random(steps) for s in group])
        rows: list[list[np.ndarray]] = [[], [], [], []]  # per step, (B, N, ...)
        for k in range(steps):
            obs = step.observation
            label = (
                teacher.act_batch(obs, step.neighbour_index) if links else teacher.act_batch(obs)
            )
            rows[0].append(obs)
            rows[1].append(np.asarray(label, dtype=np.float32))
            rows[2].append(np.asarray(step.result.min_separation, dtype=float))
            rows[3].append(np.asarray(step.result.obstacle_distance, dtype=float))
            action = label
            if learner is not None and teacher_probability < 1.0:
                own = np.asarray(learner.act_batch(obs), dtype=float)
                use_teacher = coins[:, k] < teacher_probability
                action = np.where(use_teacher[:, None, None], label, own)
            step = episodes.step(action)
        stacked = [np.stack(part, axis=1) for part in rows]  # (B, steps, N, ...)
        for copy, seed in enumerate(group):
            by_seed[seed] = tuple(  # type: ignore[assignment]
                part[copy].reshape(steps * n_uav, *part.shape[3:]) for part in stacked
            )
    return tuple(  # type: ignore[return-value]
        np.concatenate(column) for column in zip(*(by_seed[s] for s in seeds))
    )


def _learner(learner: Any | str | Path | None, scenario: Scenario, shield: bool) -> Any:
    """The learner as a policy: loaded if a path, behind the safety shield if ``shield``."""
    if isinstance(learner, (str, Path)):
        learner = make_policy(str(learner), scenario)
    if learner is not None and shield:
        learner = SafetyShield(learner, scenario)
    return learner


def _one_thread_each() -> None:
    """Worker start-up: one torch thread per process (the workers already fill the cores)."""
    try:
        import torch
    except ImportError:  # the teacher alone needs no torch
        return
    torch.set_num_threads(1)


def worker_pool(workers: int) -> Executor | None:
    """A pool of ``workers`` processes for :func:`collect_in_workers` (None for 1: no pool).

    Processes are spawned, not forked: the parent may hold torch threads or a CUDA context,
    which a forked child inherits broken."""
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    if workers == 1:
        return None
    return ProcessPoolExecutor(
        workers, mp_context=get_context("spawn"), initializer=_one_thread_each
    )


def _chunks(seeds: Sequence[int], workers: int) -> list[list[int]]:
    """``seeds`` in at most ``workers`` consecutive, non-empty chunks of near-equal length."""
    parts = np.array_split(np.asarray(seeds, dtype=int), workers)
    return [[int(s) for s in part] for part in parts if len(part)]


def collect_in_workers(
    pool: Executor | None, workers: int, seeds: Sequence[int], **settings: Any
) -> Samples:
    """:func:`collect` with the seeds split into ``workers`` consecutive chunks, one per worker
    of ``pool`` (in this process when ``pool`` is None); the samples of one :func:`collect` of
    every seed, in the same order (with a learner, up to the float32 rounding of its batched
    products, which depends on the batch size). ``settings``: :func:`collect`'s other
    arguments (a learner as a path, which a worker can load)."""
    chunks = _chunks(seeds, workers)
    if pool is None or len(chunks) < 2:
        return collect(seeds=list(seeds), **settings)
    parts = [pool.submit(collect, seeds=chunk, **settings) for chunk in chunks]
    results = [part.result() for part in parts]
    return tuple(np.concatenate(column) for column in zip(*results))  # type: ignore[return-value]


def fly(
    scenario: Scenario, learner: str | Path, seeds: Sequence[int], shield: bool = False
) -> list[EpisodeBatch]:
    """The saved policy at ``learner`` (behind the safety shield if ``shield``) flies ``seeds``
    through the project's runner (one batch per group of equal N)."""
    return run_episode_groups(scenario, _learner(learner, scenario, shield), list(seeds))


def fly_in_workers(
    pool: Executor | None,
    workers: int,
    scenario: Scenario,
    learner: str | Path,
    seeds: Sequence[int],
    shield: bool = False,
) -> list[EpisodeBatch]:
    """:func:`fly` with the seeds split into ``workers`` chunks over ``pool``; the batches of
    every chunk, in the order of the seeds. A learner's batched matrix products round
    differently for another batch size, so an episode can differ from the one flown in a
    single batch by that rounding (float32) and whatever the closed loop makes of it."""
    chunks = _chunks(seeds, workers)
    if pool is None or len(chunks) < 2:
        return fly(scenario, learner, seeds, shield)
    parts = [pool.submit(fly, scenario, learner, chunk, shield) for chunk in chunks]
    return [batch for part in parts for batch in part.result()]
