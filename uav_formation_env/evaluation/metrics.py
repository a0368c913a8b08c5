"""Episode metrics (see the package docstring) and the summary of an episode batch."""

from __future__ import annotations

from typing import Any

import numpy as np

from uav_formation_env.core.cost import anchored
from uav_formation_env.evaluation.mission import (
    MissionMetrics,
    mean_ci95,
    mission_metrics,
    mission_summary,
)
from uav_formation_env.evaluation.runner import EpisodeBatch

OBSERVER_WARMUP_S = 10.0  # observer_rms_error counts steps with t > this [s]


def _sample_std(x: np.ndarray, axis: int = 0) -> np.ndarray:
    """Standard deviation over seeds (ddof = 1; 0 for a single seed)."""
    x = np.asarray(x, dtype=float)
    if x.shape[axis] < 2:
        return np.zeros(np.delete(x.shape, axis))
    return x.std(axis=axis, ddof=1)


def formation_rmse(batch: EpisodeBatch) -> np.ndarray:
    """(B,) RMS over steps and UAVs of each UAV's position error from its formation slot [m]."""
    cfg = batch.scenario.formation
    if batch.scenes is None:
        offsets = cfg.slot_offsets  # (N, 6)
    else:  # each seed's drawn formation, (B, N, 6)
        offsets = np.stack([s.formation.slot_offsets for s in batch.scenes])
    # anchored() takes (B, N, *extra, 6): seeds first, then UAVs, then the time steps
    z = batch.z.transpose(1, 2, 0, 3)
    a = anchored(z, offsets if offsets.ndim == 3 else offsets[None])
    a = a[..., :3].transpose(2, 0, 1, 3)  # (T+1, B, N, 3)
    e = a - a.mean(axis=2, keepdims=True)
    return np.sqrt((e**2).sum(axis=-1).mean(axis=(0, 2)))


def observer_rms(batch: EpisodeBatch, after: float = OBSERVER_WARMUP_S) -> np.ndarray | None:
    """(B,) RMS of estimate - d over steps ending after ``after`` s, UAVs and axes; None without
    observer or if the episode ends before ``after``."""
    if not batch.scenario.observer.enabled:
        return None
    keep = batch.t[1:] > after + 1e-9
    if not keep.any():
        return None
    error = batch.estimate[1:][keep] - batch.disturbance[keep]  # (T', B, N, 3)
    return np.sqrt((error**2).mean(axis=(0, 2, 3)))


def obstacle_events(batch: EpisodeBatch) -> dict[str, dict[str, Any]]:
    """Per obstacle ``O1, O2, ...``: activation / restore times per seed and their mean, and the
    case (1 = one group, 2 = split)."""
    return events_of(batch.activation_time, batch.restore_time, batch.case)


def events_of(
    activation_time: np.ndarray, restore_time: np.ndarray, case: np.ndarray
) -> dict[str, dict[str, Any]]:
    """:func:`obstacle_events` of (B, O) activation and restore times [s] (NaN: never) and
    cases."""
    events = {}
    for o in range(activation_time.shape[1]):
        act, res = activation_time[:, o], restore_time[:, o]
        events[f"O{o + 1}"] = {
            "activate_s": _nan_mean(act),
            "restore_s": _nan_mean(res),
            "activate_s_per_seed": _none_for_nan(act),
            "restore_s_per_seed": _none_for_nan(res),
            "case_per_seed": [int(c) for c in case[:, o]],
        }
    return events


def _time_range(t: np.ndarray, flag: np.ndarray) -> list[float] | None:
    """[first, last] time where ``flag`` is set, or None."""
    if not flag.any():
        return None
    hit = t[flag]
    return [round(float(hit[0]), 6), round(float(hit[-1]), 6)]


def _nan_mean(x: np.ndarray) -> float | None:
    x = np.asarray(x, dtype=float)
    return None if np.isnan(x).all() else round(float(np.nanmean(x)), 6)


def _none_for_nan(x: np.ndarray) -> list[float | None]:
    return [None if np.isnan(v) else round(float(v), 6) for v in x]


def cost_terms_per_seed(batch: EpisodeBatch) -> dict[str, np.ndarray]:
    """Each term of J_i (formation, energy, terminal, velocity, separation, obstacle) realised
    over the episode, averaged over the UAVs: name -> (B,) per seed [-]. The terms add up to
    ``stage_cost`` (``J_i = sum of its terms``), so they say where a policy's realised J goes."""
    return {name: value.sum(axis=0).mean(axis=1) for name, value in batch.cost_terms.items()}


def mission_of(batch: EpisodeBatch) -> MissionMetrics:
    """The mission metrics (:mod:`~uav_formation_env.evaluation.mission`) of an episode batch."""
    return mission_metrics(
        batch.scenario, batch.t, batch.z, batch.collision, batch.min_separation, batch.scenes
    )


def summarise(batch: EpisodeBatch) -> dict[str, Any]:
    """The metrics of ``batch`` as a JSON-ready dict, each per seed and then the mean over seeds
    unless stated:

    - ``triggers_per_uav``: event-triggered steps per UAV (DMPC policies only, else null);
    - ``realised_cost_per_uav``: Σ over the episode of UAV i's stage cost J_i (the env's -reward);
    - ``formation_rmse_m``: RMS over steps and UAVs of ``||e_i||``, with ``e_i = a_i - mean_j a_j``
      the position error of UAV i from its slot in the formation anchored at the swarm's mean
      (``a = p - p^d``); it includes the deliberate splits at obstacles and the start transient;
    - ``min_obstacle_surface_distance_m`` / ``min_obstacle_center_distance_m``: minimum over seeds,
      steps and UAVs (negative surface distance = inside an obstacle);
    - ``min_separation_m``: minimum distance between two UAVs over seeds and steps;
    - ``collisions``: UAV-steps flagged as collisions, summed over seeds (the runner never ends an
      episode early, whatever ``collision.mode`` says); ``collision_time_range_s`` the first and
      last time of one;
    - ``observer_rms_error``: RMS of ``estimate - d`` over steps with t > 10 s, UAVs and axes (the
      estimate after a step against the disturbance held over that step); null without observer
      (or for episodes that end before 10 s);
    - ``events``: activation (topology change: split in case 2) and restore time of each obstacle;
    - ``optimiser_cost_ratio_median``: median over triggered UAV-steps of J_exec / J_pre, how far
      the optimiser lowered J_i below the warm start's (DMPC policies only, else null);
    - ``mission``: the mission metrics of :mod:`~uav_formation_env.evaluation.mission` (route
      error against the preset route, velocity-tracking RMSE, obstacles met, collisions and minimum
      separation after t = 0, completion rate and every failure with its seed and cause), always
      beside the cost: J_i tracks velocity, not position, so a cheap policy can leave the route;
    - ``realised_cost_ci95``: half-width of the 95 % confidence interval of the mean over seeds;
    - ``realised_cost_terms``: the realised J per UAV split into J_i's terms (formation, energy,
      terminal, velocity, separation, obstacle), which add up to ``realised_cost_mean``: where a
      policy's cost goes (``uav-formation evaluate`` prints them as "by term");
    - ``wall_time_per_step_s``: wall time of one batched control step (policy + simulation), and the
      same divided by the number of seeds.
    """
    realised = batch.stage_cost.sum(axis=0)  # (B, N)
    _, cost_ci95 = mean_ci95(realised.mean(axis=1))
    returns = batch.reward.sum(axis=0).mean(axis=1)  # (B,) per UAV
    rmse = formation_rmse(batch)
    obs_rms = observer_rms(batch)
    centre = batch.obstacle_center.min(axis=(0, 1)) if batch.obstacle_center.size else None
    surface = float(batch.obstacle_surface.min())
    collisions = batch.collision.sum(axis=(0, 2))  # (B,)
    step_time = batch.policy_seconds + batch.sim_seconds
    summary: dict[str, Any] = {
        "policy": batch.policy_name,
        "scenario": batch.scenario.name,
        "observer": bool(batch.scenario.observer.enabled),
        "seeds": list(batch.seeds),
        "duration_s": float(batch.scenario.duration),
        "n_steps": batch.n_steps,
        "triggers_per_uav": None,
        "triggers_mean": None,
        "triggers_per_uav_per_seed": None,
        "realised_cost_per_uav": realised.mean(axis=0).tolist(),
        "realised_cost_mean": float(realised.mean()),
        "realised_cost_ci95": cost_ci95,
        "realised_cost_per_seed": realised.mean(axis=1).tolist(),
        "realised_cost_terms": {
            name: float(per_seed.mean()) for name, per_seed in cost_terms_per_seed(batch).items()
        },
        # the episode layer's reward (the scenario's episode.reward), summed, mean over UAVs
        "reward": batch.scenario.episode.reward,
        "return_mean": float(returns.mean()),
        "return_ci95": mean_ci95(returns)[1],
        "return_per_seed": returns.tolist(),
        "mission": mission_summary(mission_of(batch), list(batch.seeds)),
        "formation_rmse_m": float(rmse.mean()),
        "formation_rmse_m_per_seed": rmse.tolist(),
        "min_obstacle_surface_distance_m": surface if np.isfinite(surface) else None,
        "min_obstacle_center_distance_m": None if centre is None else float(centre.min()),
        "min_obstacle_center_distance_per_obstacle_m": None
        if centre is None
        else {f"O{o + 1}": float(c) for o, c in enumerate(centre)},
        "min_separation_m": float(batch.min_separation[1:].min()),
        "collisions": int(collisions.sum()),
        "collisions_per_seed": collisions.astype(int).tolist(),
        "collision_time_range_s": _time_range(batch.t[1:], batch.collision.any(axis=(1, 2))),
        "observer_rms_error": None if obs_rms is None else float(np.mean(obs_rms)),
        "observer_rms_error_per_seed": None if obs_rms is None else obs_rms.tolist(),
        "events": obstacle_events(batch),
        "wall_time_per_step_s": float(step_time.mean()),
        "wall_time_per_step_per_episode_s": float(step_time.mean() / batch.batch_size),
        "policy_time_per_step_s": float(batch.policy_seconds.mean()),
        "seconds_per_batch": batch.wall_seconds,
        "seconds_per_episode": batch.wall_seconds / batch.batch_size,
    }
    summary["nash_gap"] = nash_gap_summary(batch)
    summary["optimiser_cost_ratio_median"] = None
    if batch.triggered is not None:
        counts = batch.triggered.sum(axis=0)  # (B, N)
        summary["triggers_per_uav"] = counts.mean(axis=0).tolist()
        summary["triggers_mean"] = float(counts.mean())
        summary["triggers_per_uav_per_seed"] = counts.astype(int).tolist()
        if batch.triggered.any() and batch.j_pre is not None and batch.j_exec is not None:
            ratio = batch.j_exec[batch.triggered] / batch.j_pre[batch.triggered]
            summary["optimiser_cost_ratio_median"] = float(np.median(ratio))
    return summary


def nash_gap_summary(batch: EpisodeBatch) -> dict[str, Any] | None:
    """Statistics of the per-step Nash gap (``run_episodes(nash_gap=True)``), else None.

    Over the UAV-steps whose plan lies in the UAV's box (elsewhere the gap can be negative: see
    :func:`~uav_formation_env.policies.nash.nash_gap`): median, 90th percentile, mean and max of
    the gap, and of the gap relative to J_i of the plan; ``in_box_fraction`` of all UAV-steps.
    """
    if batch.nash_gap is None or batch.nash_cost is None or batch.nash_in_box is None:
        return None
    inside = batch.nash_in_box
    gap = batch.nash_gap[inside]
    relative = gap / np.maximum(batch.nash_cost[inside], 1e-12)
    if gap.size == 0:
        return {"in_box_fraction": 0.0}
    return {
        "median": float(np.median(gap)),
        "p90": float(np.percentile(gap, 90)),
        "mean": float(gap.mean()),
        "max": float(gap.max()),
        "relative_median": float(np.median(relative)),
        "relative_p90": float(np.percentile(relative, 90)),
        "in_box_fraction": float(inside.mean()),
    }
