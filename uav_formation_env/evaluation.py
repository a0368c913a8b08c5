"""Batched evaluation of any policy on a scenario: episodes, per-step records and metrics.

One :class:`~uav_formation_env.sim.FormationSim` runs every seed of an evaluation as one copy of a
batch, and the policy is called once per control step on the ``(B, N, dim)`` observations of
:func:`~uav_formation_env.envs.parallel.observations_of` (exactly what the PettingZoo env hands
its agents). A policy is anything with

- ``act_batch(obs) -> actions``: ``(B, N, dim)`` observations to ``(B, N, 3)`` normalised actions
  in [-1, 1] (``u_n = a · u_max``);
- optionally ``reset(batch_size)``, called once before the first step;
- optionally ``records()`` returning per-step arrays ``triggered``, ``j_pre`` and ``j_exec`` of
  shape (T, B, N) (as :meth:`~uav_formation_env.policies.dmpc.NashDMPCPolicy.records` does).

Adapters here: :class:`RandomPolicy`, :class:`HeuristicPolicy` (the consensus PD controller acting
from decoded observations) and :class:`SB3Policy` (a saved stable-baselines3 model, loaded lazily).
:func:`make_policy` builds any of them, or the reference DMPC, from a name.

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
- ``wall_time_per_step_s``: wall time of one batched control step (policy + simulation), and the
  same divided by the number of seeds.
"""

from __future__ import annotations

import csv
import json
import pickle
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from tqdm import tqdm

from uav_formation_env.config import Scenario
from uav_formation_env.config_io import with_overrides
from uav_formation_env.core.cost import anchored, relative_offset_sign
from uav_formation_env.core.observation import decode_observations, others_index
from uav_formation_env.core.topology import obstacle_distances
from uav_formation_env.envs.parallel import observations_of
from uav_formation_env.policies.heuristic import ConsensusGains, consensus_pd
from uav_formation_env.sim import FormationSim

DMPC_OPTIMIZERS = ("lfpio", "pio", "pso")
POLICY_NAMES = (*DMPC_OPTIMIZERS, "heuristic", "random")
OBSERVER_WARMUP_S = 10.0  # observer_rms_error counts steps with t > this [s]
SB3_ALGORITHMS = ("PPO", "SAC", "TD3", "A2C", "DDPG")


class BatchPolicy(Protocol):
    """What :func:`run_episodes` needs of a policy."""

    def act_batch(self, obs: np.ndarray) -> np.ndarray: ...


# ---------------------------------------------------------------------------------------- policies
class RandomPolicy:
    """Uniform random normalised actions in [-1, 1]^3 (a lower bound on any controller).

    Args:
        seed: seed of the one random generator.
    """

    def __init__(self, seed: int | None = None) -> None:
        self.rng = np.random.default_rng(seed)

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        batch, n_uav = np.shape(obs)[:2]
        return self.rng.uniform(-1.0, 1.0, size=(batch, n_uav, 3))


class HeuristicPolicy:
    """The consensus PD controller (:func:`~uav_formation_env.policies.heuristic.consensus_pd`)
    acting from observations only.

    UAV i rebuilds the swarm in its own frame from its observation: own anchored position 0, own
    velocity, the other UAVs' states from the observed relative formation errors plus the known
    offsets, its neighbour flags as its row of H and its reference velocity; then the shared
    control law is evaluated on that view and UAV i's row is kept. Up to the float32 rounding of
    the observation this is the input the law gives on the simulator's arrays.

    Args:
        scenario: formation offsets, u_max and the offset convention (mission data).
        gains: the PD gains (None: the defaults).
    """

    def __init__(self, scenario: Scenario, gains: ConsensusGains | None = None) -> None:
        self.n_uav = scenario.n_uav
        self.u_max = scenario.dynamics.u_max
        self.offsets = np.asarray(scenario.formation.offsets, dtype=float)
        self.mirrored = scenario.formation.mirrored_offsets
        self.gains = ConsensusGains() if gains is None else gains

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=float)
        batch, n = obs.shape[:2]
        decoded = decode_observations(obs, n)
        sign = relative_offset_sign(self.mirrored)
        own = np.arange(n)
        index = others_index(n)  # (N, N-1)
        # anchored states a of every UAV as UAV i sees them (own: position 0), (B, N_i, N, 6)
        a_own = np.zeros((batch, n, 6))
        a_own[..., 3:] = decoded.velocity - sign * self.offsets[:, 3:]
        view = np.empty((batch, n, n, 6))
        view[:, own, own] = a_own
        view[:, own[:, None], index] = a_own[:, :, None] + decoded.relative_formation_error
        z = view + sign * self.offsets  # back from anchored to states
        adjacency = np.zeros((batch, n, n, n))
        adjacency[:, own[:, None], own[:, None], index] = decoded.neighbour
        reference = np.broadcast_to(decoded.reference_velocity[:, :, None], (batch, n, n, 3)).copy()
        u = consensus_pd(
            z.reshape(batch * n, n, 6),
            reference.reshape(batch * n, n, 3),
            adjacency.reshape(batch * n, n, n),
            self.offsets,
            self.u_max,
            self.gains,
            self.mirrored,
        ).reshape(batch, n, n, 3)
        return u[:, own, own] / self.u_max


class SB3Policy:
    """A saved stable-baselines3 model shared by every UAV (parameter sharing).

    stable-baselines3 is imported only here, when the model is loaded (the ``[rl]`` extra). The
    algorithm is ``algo`` or, if None, the first of :data:`SB3_ALGORITHMS` that loads the file.
    If ``vecnormalize.pkl`` lies beside the model, observations are normalised with its running
    statistics (not updated). Predictions are deterministic, on ``(B·N, dim)`` observations.

    Args:
        path: the model's ``.zip``.
        algo: algorithm class name (``"PPO"``, ``"SAC"``, ...) or None to try each.
        device: torch device.
    """

    def __init__(self, path: str | Path, algo: str | None = None, device: str = "cpu") -> None:
        import stable_baselines3

        self.path = Path(path)
        if not self.path.is_file() and self.path.with_suffix(".zip").is_file():
            self.path = self.path.with_suffix(".zip")
        if not self.path.is_file():
            raise ValueError(f"no stable-baselines3 model at {path!s}")
        names = [algo.upper()] if algo else list(SB3_ALGORITHMS)
        errors = []
        self.model = None
        for name in names:
            cls = getattr(stable_baselines3, name, None)
            if cls is None:
                errors.append(f"{name}: not a stable-baselines3 algorithm")
                continue
            try:
                self.model = cls.load(str(self.path), device=device)
                self.algo = name
                break
            except Exception as error:  # noqa: BLE001 - try the next algorithm
                errors.append(f"{name}: {type(error).__name__}: {error}")
        if self.model is None:
            raise ValueError(f"could not load {self.path} as {names}: " + "; ".join(errors))
        self.normalizer = None
        stats = self.path.parent / "vecnormalize.pkl"
        if stats.is_file():
            with open(stats, "rb") as stream:
                self.normalizer = pickle.load(stream)  # VecNormalize without its venv
            self.normalizer.training = False

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        batch, n, dim = obs.shape
        flat = obs.reshape(batch * n, dim)
        if self.normalizer is not None:
            flat = self.normalizer.normalize_obs(flat)
        actions, _ = self.model.predict(flat, deterministic=True)
        return np.clip(np.asarray(actions, dtype=float).reshape(batch, n, 3), -1.0, 1.0)


def make_policy(
    name: str, scenario: Scenario, seed: int | None = 0, algo: str | None = None
) -> BatchPolicy:
    """A policy from a name: ``lfpio``, ``pio``, ``pso`` (the reference DMPC with that optimiser),
    ``heuristic``, ``random``, or the path of a stable-baselines3 model.

    Args:
        name: policy name or model path.
        scenario: the scenario the policy flies (mission data of DMPC / heuristic).
        seed: seed of the policy's random generator (DMPC optimisers, random actions).
        algo: stable-baselines3 algorithm of a model path (None: try each).
    """
    key = name.lower()
    if key in DMPC_OPTIMIZERS:
        from uav_formation_env.policies.dmpc import NashDMPCPolicy

        return NashDMPCPolicy(scenario, key, seed=seed)
    if key == "heuristic":
        return HeuristicPolicy(scenario)
    if key == "random":
        return RandomPolicy(seed)
    path = Path(name)
    if path.is_file() or path.with_suffix(".zip").is_file():
        return SB3Policy(path, algo)
    raise ValueError(
        f"unknown policy {name!r}: expected one of {list(POLICY_NAMES)} or the path of a "
        "stable-baselines3 model (.zip)"
    )


# ---------------------------------------------------------------------------------------- runner
@dataclass
class EpisodeBatch:
    """Every step of B episodes run together (one per seed); T control steps, N UAVs, O obstacles.

    Arrays indexed ``[k]`` over T + 1 hold the state at time ``t[k]`` (k = 0 is the reset);
    arrays over T hold what happened during step k + 1 (from ``t[k]`` to ``t[k + 1]``).
    """

    scenario: Scenario
    seeds: list[int]
    policy_name: str
    t: np.ndarray  # (T+1,) [s]
    z: np.ndarray  # (T+1, B, N, 6) [m, m/s]
    reference_velocity: np.ndarray  # (T+1, B, N, 3) [m/s]
    estimate: np.ndarray  # (T+1, B, N, 3) observer estimate [m/s^2]
    groups: np.ndarray  # (T+1, B, N) sub-formation id
    min_separation: np.ndarray  # (T+1, B, N) [m]
    obstacle_surface: np.ndarray  # (T+1, B, N) nearest obstacle surface [m]
    obstacle_center: np.ndarray  # (T+1, B, O) min over UAVs of the distance to each centre [m]
    u_n: np.ndarray  # (T, B, N, 3) formation input [m/s^2]
    u_applied: np.ndarray  # (T, B, N, 3) [m/s^2]
    disturbance: np.ndarray  # (T, B, N, 3) [m/s^2]
    stage_cost: np.ndarray  # (T, B, N) J_i stage cost of the transition
    cost_terms: dict[str, np.ndarray]  # name -> (T, B, N)
    collision: np.ndarray  # (T, B, N) bool, after the step
    activation_time: np.ndarray  # (B, O) [s], NaN if never
    restore_time: np.ndarray  # (B, O) [s], NaN if never
    case: np.ndarray  # (B, O) 1 one group, 2 split, 0 never activated
    triggered: np.ndarray | None  # (T, B, N) policy's event trigger (DMPC), else None
    j_pre: np.ndarray | None  # (T, B, N)
    j_exec: np.ndarray | None  # (T, B, N)
    policy_seconds: np.ndarray  # (T,) wall time of act_batch per step [s]
    sim_seconds: np.ndarray  # (T,) wall time of the simulation step + observations [s]

    @property
    def n_steps(self) -> int:
        return len(self.t) - 1

    @property
    def batch_size(self) -> int:
        return len(self.seeds)

    @property
    def wall_seconds(self) -> float:
        return float(self.policy_seconds.sum() + self.sim_seconds.sum())


ProgressLike = bool | Callable[[int], None]


def run_episodes(
    scenario: Scenario,
    policy: BatchPolicy,
    seeds: Sequence[int],
    *,
    duration: float | None = None,
    policy_name: str = "",
    progress: ProgressLike = False,
    desc: str | None = None,
) -> EpisodeBatch:
    """Run one episode per seed, all seeds as one batch, with one ``act_batch`` call per step.

    Copy b is seeded with ``seeds[b]`` (a copy reproduces a one-seed run of that seed).

    Args:
        scenario: the scenario.
        policy: see the module docstring; it must have been built for ``scenario`` with the same
            ``duration`` (the observation carries t / duration).
        seeds: one seed per episode.
        duration: episode length [s] overriding the scenario's (None: the scenario's).
        policy_name: label stored in the result.
        progress: True for a tqdm bar over the steps, or a callable given the number of steps
            done since its last call.
        desc: label of the progress bar.
    """
    if duration is not None:
        scenario = with_overrides(scenario, {"duration": float(duration)})
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("need at least one seed")
    batch, n_steps = len(seeds), scenario.n_steps
    sim = FormationSim(scenario, batch_size=batch)
    if hasattr(policy, "reset"):
        policy.reset(batch)
    start = time.perf_counter()
    result = sim.reset(seed=seeds)
    obs = observations_of(sim, result)

    def centre_min(z: np.ndarray) -> np.ndarray:
        if len(sim.obstacle_radii) == 0:
            return np.zeros((batch, 0))
        return obstacle_distances(z[..., :3], scenario.avoidance).min(axis=1)

    states = [_state_record(result, centre_min)]
    steps: list[tuple] = []
    policy_seconds = np.zeros(n_steps)
    sim_seconds = np.zeros(n_steps)
    sim_seconds_reset = time.perf_counter() - start
    bar = None
    callback = progress if callable(progress) else None
    if progress is True:
        bar = tqdm(total=n_steps, desc=desc or policy_name or "episodes", unit="step")
    for k in range(n_steps):
        t0 = time.perf_counter()
        actions = np.asarray(policy.act_batch(obs), dtype=float)
        t1 = time.perf_counter()
        if actions.shape != (batch, scenario.n_uav, 3):
            raise ValueError(
                f"policy returned actions of shape {actions.shape}, "
                f"expected {(batch, scenario.n_uav, 3)}"
            )
        result = sim.step(np.clip(actions, -1.0, 1.0) * sim.u_max)
        obs = observations_of(sim, result)
        policy_seconds[k] = t1 - t0
        sim_seconds[k] = time.perf_counter() - t1
        states.append(_state_record(result, centre_min))
        steps.append(
            (
                result.u_n,
                result.u_applied,
                result.disturbance,
                result.cost.total,
                result.cost.as_dict(),
                result.collision,
            )
        )
        if bar is not None:
            bar.update(1)
        elif callback is not None:
            callback(1)
    if bar is not None:
        bar.close()
    sim_seconds[0] += sim_seconds_reset
    triggered = j_pre = j_exec = None
    if hasattr(policy, "records"):
        records = policy.records()
        if getattr(records, "triggered", None) is not None and len(records.triggered) == n_steps:
            triggered = np.asarray(records.triggered, dtype=bool)
            j_pre = np.asarray(records.j_pre, dtype=float)
            j_exec = np.asarray(records.j_exec, dtype=float)
    u_n, u_applied, disturbance, stage, terms, collision = zip(*steps)
    topo = sim.topology
    return EpisodeBatch(
        scenario=scenario,
        seeds=seeds,
        policy_name=policy_name,
        t=np.arange(n_steps + 1) * scenario.dynamics.dt,
        z=np.stack([s[0] for s in states]),
        reference_velocity=np.stack([s[1] for s in states]),
        estimate=np.stack([s[2] for s in states]),
        groups=np.stack([s[3] for s in states]),
        min_separation=np.stack([s[4] for s in states]),
        obstacle_surface=np.stack([s[5] for s in states]),
        obstacle_center=np.stack([s[6] for s in states]),
        u_n=np.stack(u_n),
        u_applied=np.stack(u_applied),
        disturbance=np.stack(disturbance),
        stage_cost=np.stack(stage),
        cost_terms={name: np.stack([t[name] for t in terms]) for name in terms[0]},
        collision=np.stack(collision),
        activation_time=np.asarray(topo.activation_time, dtype=float).copy(),
        restore_time=np.asarray(topo.restore_time, dtype=float).copy(),
        case=np.asarray(topo.case, dtype=int).copy(),
        triggered=triggered,
        j_pre=j_pre,
        j_exec=j_exec,
        policy_seconds=policy_seconds,
        sim_seconds=sim_seconds,
    )


def _state_record(result, centre_min) -> tuple[np.ndarray, ...]:
    return (
        result.z,
        result.reference_velocity,
        result.estimate,
        result.groups,
        result.min_separation,
        result.obstacle_distance,
        centre_min(result.z),
    )


# ---------------------------------------------------------------------------------------- metrics
def _sample_std(x: np.ndarray, axis: int = 0) -> np.ndarray:
    """Standard deviation over seeds (ddof = 1; 0 for a single seed)."""
    x = np.asarray(x, dtype=float)
    if x.shape[axis] < 2:
        return np.zeros(np.delete(x.shape, axis))
    return x.std(axis=axis, ddof=1)


def formation_rmse(batch: EpisodeBatch) -> np.ndarray:
    """(B,) RMS over steps and UAVs of each UAV's position error from its formation slot [m]."""
    cfg = batch.scenario.formation
    z = batch.z.reshape(-1, *batch.z.shape[2:])  # (T+1)·B rows of (N, 6)
    a = anchored(z, np.asarray(cfg.offsets, dtype=float), cfg.mirrored_offsets)[..., :3]
    a = a.reshape(*batch.z.shape[:3], 3)
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
    events = {}
    for o in range(batch.activation_time.shape[1]):
        act = batch.activation_time[:, o]
        res = batch.restore_time[:, o]
        events[f"O{o + 1}"] = {
            "activate_s": _nan_mean(act),
            "restore_s": _nan_mean(res),
            "activate_s_per_seed": _none_for_nan(act),
            "restore_s_per_seed": _none_for_nan(res),
            "case_per_seed": [int(c) for c in batch.case[:, o]],
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


def summarise(batch: EpisodeBatch) -> dict[str, Any]:
    """The metrics of the module docstring as a JSON-ready dict."""
    realised = batch.stage_cost.sum(axis=0)  # (B, N)
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
        "realised_cost_per_seed": realised.mean(axis=1).tolist(),
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


# ---------------------------------------------------------------------------------------- output
def json_ready(obj: Any) -> Any:
    """``obj`` with every non-finite float replaced by None (so the JSON is standard)."""
    if isinstance(obj, dict):
        return {k: json_ready(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_ready(v) for v in obj]
    if isinstance(obj, float | np.floating) and not np.isfinite(obj):
        return None
    return obj


def write_json(obj: Any, path: str | Path) -> None:
    """Standard JSON (non-finite floats as null), indented."""
    Path(path).write_text(json.dumps(json_ready(obj), indent=2, allow_nan=False))


RECORD_COLUMNS = (
    ["seed", "step", "t", "uav", "x", "y", "z", "vx", "vy", "vz", "vref_x", "vref_y", "vref_z"]
    + ["un_x", "un_y", "un_z", "u_x", "u_y", "u_z", "d_x", "d_y", "d_z"]
    + ["dhat_x", "dhat_y", "dhat_z", "group", "J_stage", "obstacle_surface_m", "min_separation_m"]
    + ["collision", "triggered", "J_pre", "J_exec"]
)


def write_records(batch: EpisodeBatch, path: str | Path) -> None:
    """Per-step CSV, one row per seed, step (1..T) and UAV (1..N), columns
    :data:`RECORD_COLUMNS`: the state, reference, estimate, group and distances after the step;
    the inputs, disturbance and stage cost of the step; the policy's trigger and J values of the
    decision that produced the step's input (empty for policies without records)."""
    T, B, N = batch.stage_cost.shape
    seed = np.broadcast_to(np.asarray(batch.seeds)[None, :, None], (T, B, N))
    step = np.broadcast_to(np.arange(1, T + 1)[:, None, None], (T, B, N))
    t = np.broadcast_to(batch.t[1:, None, None], (T, B, N))
    uav = np.broadcast_to(np.arange(1, N + 1)[None, None, :], (T, B, N))
    empty = np.full((T, B, N), np.nan)
    columns = [
        seed,
        step,
        t,
        uav,
        *np.moveaxis(batch.z[1:], -1, 0),
        *np.moveaxis(batch.reference_velocity[1:], -1, 0),
        *np.moveaxis(batch.u_n, -1, 0),
        *np.moveaxis(batch.u_applied, -1, 0),
        *np.moveaxis(batch.disturbance, -1, 0),
        *np.moveaxis(batch.estimate[1:], -1, 0),
        batch.groups[1:],
        batch.stage_cost,
        batch.obstacle_surface[1:],
        batch.min_separation[1:],
        batch.collision,
        empty if batch.triggered is None else batch.triggered,
        empty if batch.j_pre is None else batch.j_pre,
        empty if batch.j_exec is None else batch.j_exec,
    ]
    # rows ordered by seed, then step, then UAV
    table = np.stack([np.moveaxis(np.asarray(c, dtype=float), 1, 0) for c in columns], axis=-1)
    table = table.reshape(-1, len(columns))
    integer = {"seed", "step", "uav", "group", "collision", "triggered"}
    formats = ["%d" if name in integer else "%.6g" for name in RECORD_COLUMNS]
    if batch.triggered is None:
        formats[RECORD_COLUMNS.index("triggered")] = "%.6g"
    with open(path, "w", newline="") as stream:
        stream.write(",".join(RECORD_COLUMNS) + "\n")
        np.savetxt(stream, table, fmt=formats, delimiter=",")


def read_records(path: str | Path) -> list[dict[str, str]]:
    """The rows of a :func:`write_records` CSV as dicts (for tests and quick looks)."""
    with open(path, newline="") as stream:
        return list(csv.DictReader(stream))
