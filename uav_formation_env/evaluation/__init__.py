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

Metrics: :func:`summarise` (its docstring lists every key, with units).
"""

from uav_formation_env.evaluation.digest import (
    BatchDigest,
    digest,
    fly_in_chunks,
    summarise_digests,
    summarise_groups,
)
from uav_formation_env.evaluation.metrics import (
    OBSERVER_WARMUP_S,
    formation_rmse,
    mission_of,
    nash_gap_summary,
    observer_rms,
    obstacle_events,
    summarise,
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
    "BatchDigest",
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
    "digest",
    "fly_in_chunks",
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
    "summarise_digests",
    "summarise_groups",
    "write_json",
    "write_records",
]
