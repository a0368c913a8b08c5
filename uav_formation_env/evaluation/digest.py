"""Summaries of seeds flown in chunks: each batch is reduced to a small digest as soon as it is
flown, and the digests merge into the summary of every seed at once (:func:`summarise_digests`),
so that ``--seeds K`` needs one chunk of episodes in memory, not K.

Every seed's numbers depend on its seed alone, so a summary merged from chunks equals the summary
of one batch of every seed, up to the wall times and float rounding of the means.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from uav_formation_env.evaluation.metrics import (
    cost_terms_per_seed,
    events_of,
    mission_of,
    summarise,
)
from uav_formation_env.evaluation.mission import (
    MissionMetrics,
    concatenate_missions,
    mean_ci95,
    mission_summary,
)
from uav_formation_env.evaluation.runner import EpisodeBatch, run_episodes
from uav_formation_env.scenes import seeds_by_n_uav


@dataclass(frozen=True)
class BatchDigest:
    """What the summary needs of one batch of B episodes of N UAVs (O obstacles)."""

    summary: dict[str, Any]  # summarise(batch)
    mission: MissionMetrics
    cost_terms: dict[str, np.ndarray]  # J_i's term -> (B,) realised per UAV [-]
    activation_time: np.ndarray  # (B, O) [s], NaN if never
    restore_time: np.ndarray  # (B, O) [s], NaN if never
    case: np.ndarray  # (B, O)
    optimiser_ratios: np.ndarray | None  # J_exec / J_pre over the triggered UAV-steps
    n_uav: int


def digest(batch: EpisodeBatch) -> BatchDigest:
    """The digest of ``batch`` (the batch itself can then be dropped)."""
    ratios = None
    if batch.triggered is not None and batch.j_pre is not None and batch.j_exec is not None:
        ratios = batch.j_exec[batch.triggered] / batch.j_pre[batch.triggered]
    if batch.nash_gap is not None:
        raise ValueError("digest: Nash gap statistics (medians over UAV-steps) do not merge")
    return BatchDigest(
        summary=summarise(batch),
        mission=mission_of(batch),
        cost_terms=cost_terms_per_seed(batch),
        activation_time=batch.activation_time,
        restore_time=batch.restore_time,
        case=batch.case,
        optimiser_ratios=ratios,
        n_uav=batch.z.shape[2],
    )


def fly_in_chunks(
    scenario: Any,
    policy: Any,
    seeds: Sequence[int],
    chunk_size: int,
    on_batch: Callable[[EpisodeBatch], None] | None = None,
    **options: Any,
) -> list[BatchDigest]:
    """Fly ``seeds`` as batches of at most ``chunk_size`` seeds of one N (groups in ascending N,
    seeds in order within one), call ``on_batch`` on each batch and keep its digest only.

    ``options`` are those of :func:`~uav_formation_env.evaluation.run_episodes`; a progress
    bar's label gets the chunk.
    """
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")
    groups = seeds_by_n_uav(scenario, list(seeds))
    chunks = [
        (n_uav, group[start : start + chunk_size])
        for n_uav, group in groups.items()
        for start in range(0, len(group), chunk_size)
    ]
    label = options.pop("desc", None) or options.get("policy_name") or "episodes"
    digests = []
    for k, (n_uav, chunk) in enumerate(chunks):
        desc = label if len(chunks) == 1 else f"{label} [{k + 1}/{len(chunks)}]"
        if len(groups) > 1:
            desc += f", N={n_uav}"
            options["n_uav"] = n_uav
        batch = run_episodes(scenario, policy, chunk, desc=desc, **options)
        if on_batch is not None:
            on_batch(batch)
        digests.append(digest(batch))
        del batch
    return digests


def summarise_groups(batches: Sequence[EpisodeBatch]) -> dict[str, Any]:
    """The summary of the groups of :func:`~uav_formation_env.evaluation.run_episode_groups`
    (one group: :func:`~uav_formation_env.evaluation.summarise` of it, unchanged).

    Over several groups (a distribution over N): the cost, mission, separation, collision,
    trigger and timing entries over every seed (seeds in group order), ``n_uav_per_seed``, and
    each group's own summary under ``groups`` (keyed by N).
    """
    return summarise_digests([digest(batch) for batch in batches])


def summarise_digests(parts: Sequence[BatchDigest]) -> dict[str, Any]:
    """The summary of every seed of ``parts``: for one N the keys of
    :func:`~uav_formation_env.evaluation.summarise`; over several N those of
    :func:`~uav_formation_env.evaluation.summarise_groups` (each N's own summary under
    ``groups``)."""
    if not parts:
        raise ValueError("summarise_digests needs at least one digest")
    by_n: dict[int, list[BatchDigest]] = {}
    for part in parts:
        by_n.setdefault(part.n_uav, []).append(part)
    merged = [_merge_same_n(group) for _, group in sorted(by_n.items())]
    return merged[0].summary if len(merged) == 1 else _across_n(merged)


def _joined(summaries: Sequence[dict[str, Any]], key: str) -> list[Any]:
    return [value for summary in summaries for value in summary[key]]


def _min_or_none(values: Sequence[float | None]) -> float | None:
    present = [v for v in values if v is not None]
    return min(present) if present else None


def _merge_same_n(parts: Sequence[BatchDigest]) -> BatchDigest:
    """One digest of the batches ``parts`` of one N (seeds in their order)."""
    if len(parts) == 1:
        return parts[0]
    summaries = [p.summary for p in parts]
    first = summaries[0]
    seeds = _joined(summaries, "seeds")
    sizes = [len(s["seeds"]) for s in summaries]
    realised = np.asarray(_joined(summaries, "realised_cost_per_seed"))
    returns = np.asarray(_joined(summaries, "return_per_seed"))
    terms = {k: np.concatenate([p.cost_terms[k] for p in parts]) for k in parts[0].cost_terms}
    mission = concatenate_missions([p.mission for p in parts])
    activation = np.concatenate([p.activation_time for p in parts])
    restore = np.concatenate([p.restore_time for p in parts])
    case = np.concatenate([p.case for p in parts])
    ratios = None
    if all(p.optimiser_ratios is not None for p in parts):
        ratios = np.concatenate([p.optimiser_ratios for p in parts])
    step_time = sum(s["wall_time_per_step_s"] for s in summaries)
    seconds = sum(s["seconds_per_batch"] for s in summaries)
    summary = {
        **first,
        "seeds": seeds,
        "realised_cost_per_uav": np.average(
            [s["realised_cost_per_uav"] for s in summaries], axis=0, weights=sizes
        ).tolist(),
        "realised_cost_mean": float(realised.mean()),
        "realised_cost_ci95": mean_ci95(realised)[1],
        "realised_cost_per_seed": realised.tolist(),
        "realised_cost_terms": {name: float(value.mean()) for name, value in terms.items()},
        "return_mean": float(returns.mean()),
        "return_ci95": mean_ci95(returns)[1],
        "return_per_seed": returns.tolist(),
        "mission": mission_summary(mission, seeds),
        "formation_rmse_m": float(np.mean(_joined(summaries, "formation_rmse_m_per_seed"))),
        "formation_rmse_m_per_seed": _joined(summaries, "formation_rmse_m_per_seed"),
        "min_obstacle_surface_distance_m": _min_or_none(
            [s["min_obstacle_surface_distance_m"] for s in summaries]
        ),
        "min_obstacle_center_distance_m": _min_or_none(
            [s["min_obstacle_center_distance_m"] for s in summaries]
        ),
        "min_obstacle_center_distance_per_obstacle_m": _per_obstacle_min(summaries),
        "min_separation_m": min(s["min_separation_m"] for s in summaries),
        "collisions": sum(s["collisions"] for s in summaries),
        "collisions_per_seed": _joined(summaries, "collisions_per_seed"),
        "collision_time_range_s": _time_range(summaries),
        "observer_rms_error": None,
        "observer_rms_error_per_seed": None,
        "events": events_of(activation, restore, case),
        "wall_time_per_step_s": step_time,
        "wall_time_per_step_per_episode_s": step_time / len(seeds),
        "policy_time_per_step_s": sum(s["policy_time_per_step_s"] for s in summaries),
        "seconds_per_batch": seconds,
        "seconds_per_episode": seconds / len(seeds),
        "nash_gap": None,
        "optimiser_cost_ratio_median": None
        if ratios is None or not ratios.size
        else float(np.median(ratios)),
    }
    if first["observer_rms_error"] is not None:
        per_seed = _joined(summaries, "observer_rms_error_per_seed")
        summary["observer_rms_error"] = float(np.mean(per_seed))
        summary["observer_rms_error_per_seed"] = per_seed
    if first["triggers_per_uav"] is not None:
        counts = np.asarray(_joined(summaries, "triggers_per_uav_per_seed"))
        summary["triggers_per_uav"] = counts.mean(axis=0).tolist()
        summary["triggers_mean"] = float(counts.mean())
        summary["triggers_per_uav_per_seed"] = counts.tolist()
    return BatchDigest(summary, mission, terms, activation, restore, case, ratios, parts[0].n_uav)


def _per_obstacle_min(summaries: Sequence[dict[str, Any]]) -> dict[str, float] | None:
    tables = [s["min_obstacle_center_distance_per_obstacle_m"] for s in summaries]
    if tables[0] is None:
        return None
    return {name: min(table[name] for table in tables) for name in tables[0]}


def _time_range(summaries: Sequence[dict[str, Any]]) -> list[float] | None:
    ranges = [s["collision_time_range_s"] for s in summaries if s["collision_time_range_s"]]
    if not ranges:
        return None
    return [min(r[0] for r in ranges), max(r[1] for r in ranges)]


def _across_n(parts: Sequence[BatchDigest]) -> dict[str, Any]:
    """The summary over groups of different N (each one digest), groups in ascending N."""
    summaries = [p.summary for p in parts]
    first = summaries[0]
    seeds = _joined(summaries, "seeds")
    realised = np.asarray(_joined(summaries, "realised_cost_per_seed"))
    mean, cost_ci95 = mean_ci95(realised)
    returns = np.asarray(_joined(summaries, "return_per_seed"))
    triggers = [s["triggers_per_uav_per_seed"] for s in summaries]
    per_seed_triggers = (
        None
        if any(t is None for t in triggers)
        else [float(np.mean(row)) for t in triggers for row in t]
    )
    seconds = sum(s["seconds_per_batch"] for s in summaries)
    terms = [p.cost_terms for p in parts]
    return {
        "policy": first["policy"],
        "scenario": first["scenario"],
        "observer": first["observer"],
        "seeds": seeds,
        "n_uav_per_seed": [p.n_uav for p in parts for _ in p.summary["seeds"]],
        "duration_s": first["duration_s"],
        "n_steps": first["n_steps"],
        "triggers_mean": None if per_seed_triggers is None else float(np.mean(per_seed_triggers)),
        "triggers_per_seed": per_seed_triggers,
        "realised_cost_mean": mean,
        "realised_cost_ci95": cost_ci95,
        "realised_cost_per_seed": realised.tolist(),
        "realised_cost_terms": {
            name: float(np.concatenate([t[name] for t in terms]).mean()) for name in terms[0]
        },
        "reward": first["reward"],
        "return_mean": float(returns.mean()),
        "return_ci95": mean_ci95(returns)[1],
        "return_per_seed": returns.tolist(),
        "mission": mission_summary(concatenate_missions([p.mission for p in parts]), seeds),
        "formation_rmse_m": float(np.mean(_joined(summaries, "formation_rmse_m_per_seed"))),
        "formation_rmse_m_per_seed": _joined(summaries, "formation_rmse_m_per_seed"),
        "min_separation_m": min(s["min_separation_m"] for s in summaries),
        "collisions": sum(s["collisions"] for s in summaries),
        "collisions_per_seed": _joined(summaries, "collisions_per_seed"),
        "seconds_per_batch": seconds,
        "seconds_per_episode": seconds / len(seeds),
        # one control step of every seed: the groups' batched calls one after the other
        "policy_time_per_step_s": sum(s["policy_time_per_step_s"] for s in summaries),
        "wall_time_per_step_s": seconds / first["n_steps"],
        "groups": {str(p.n_uav): s for p, s in zip(parts, summaries, strict=True)},
    }
