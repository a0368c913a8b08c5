"""Batched evaluation of any policy on a scenario: episodes, per-step records and metrics.

One :class:`~uav_formation_env.sim.FormationSim` runs every seed of an evaluation as one copy of a
batch, and the policy is called once per control step on the ``(B, N, dim)`` observations of
:func:`~uav_formation_env.episode.observations_of` (exactly what the PettingZoo env hands
its agents). A policy is anything with

- ``act_batch(obs) -> actions``: ``(B, N, dim)`` observations to ``(B, N, 3)`` normalised actions
  in [-1, 1] (``u_n = a · u_max``);
- optionally ``reset(batch_size)``, called once before the first step;
- optionally ``records()`` returning per-step arrays ``triggered``, ``j_pre`` and ``j_exec`` of
  shape (T, B, N) (as :meth:`~uav_formation_env.policies.dmpc.NashDMPCPolicy.records` does).

Re-exported from :mod:`uav_formation_env.policies`: :class:`RandomPolicy`, :class:`HeuristicPolicy`
(the consensus PD controller acting from decoded observations), :class:`SB3Policy` (a saved
stable-baselines3 model, loaded lazily), and :func:`make_policy`, which builds any of them, or the
reference DMPC, from a name of :data:`POLICY_NAMES` (:mod:`uav_formation_env.policies.registry`).

Metrics (:func:`summarise`), each per seed and then mean over seeds unless stated:

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

from uav_formation_env.evaluation.metrics import (
    OBSERVER_WARMUP_S,
    formation_rmse,
    mission_of,
    nash_gap_summary,
    observer_rms,
    obstacle_events,
    summarise,
    summarise_groups,
)
from uav_formation_env.evaluation.mission import (
    MissionMetrics,
    concatenate_missions,
    mean_ci95,
    mission_metrics,
    mission_summary,
    mission_table,
    preset_route,
    wilson_ci95,
)
from uav_formation_env.evaluation.output import (
    RECORD_COLUMNS,
    json_ready,
    read_records,
    write_json,
    write_records,
)
from uav_formation_env.evaluation.runner import (
    EpisodeBatch,
    ProgressLike,
    concatenate_batches,
    policy_plans,
    run_episode_groups,
    run_episodes,
)
from uav_formation_env.policies.learned import SB3_ALGORITHMS, SB3Policy
from uav_formation_env.policies.registry import (
    DMPC_OPTIMIZERS,
    POLICY_NAMES,
    BatchPolicy,
    make_policy,
)
from uav_formation_env.policies.simple import HeuristicPolicy, RandomPolicy

__all__ = [
    "DMPC_OPTIMIZERS",
    "OBSERVER_WARMUP_S",
    "POLICY_NAMES",
    "RECORD_COLUMNS",
    "SB3_ALGORITHMS",
    "BatchPolicy",
    "EpisodeBatch",
    "HeuristicPolicy",
    "MissionMetrics",
    "ProgressLike",
    "RandomPolicy",
    "SB3Policy",
    "formation_rmse",
    "concatenate_batches",
    "concatenate_missions",
    "json_ready",
    "make_policy",
    "mean_ci95",
    "wilson_ci95",
    "mission_metrics",
    "mission_of",
    "mission_summary",
    "mission_table",
    "nash_gap_summary",
    "observer_rms",
    "obstacle_events",
    "policy_plans",
    "preset_route",
    "read_records",
    "run_episode_groups",
    "run_episodes",
    "summarise",
    "summarise_groups",
    "write_json",
    "write_records",
]
